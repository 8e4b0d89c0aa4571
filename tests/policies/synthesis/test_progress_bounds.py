"""What a synthesis tells its progress after each round are the bounds its result will show so far:
never an L below one already reached (a new search starting from 0), never a U of another
probability (a search within fewer junctions than the unbounded problem asked), and no L at all
before there is one to show (the trust-state synthesis' L is a valued policy's)."""

from __future__ import annotations

from trustroute.policies.logic.spec import load_spec
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.settings import SynthesisSettings
from trustroute.policies.trust_state_synthesis.synthesis import synthesize_joint

# a fixed amount of work (policies/work_clock.py): the same rounds on any machine
UNBOUNDED = SynthesisSettings(horizon=None, work_limit=1_000_000, time_limit=900.0)
ROUNDING = 1e-9   # the result's bounds are the computed ones widened outward (rounding.py)


def _told(synthesis, pomdp, spec) -> tuple[list[tuple[float | None, float]], object]:
    told: list[tuple[float | None, float]] = []
    result = synthesis(pomdp, spec, UNBOUNDED, on_iteration=lambda lower, upper: told.append((lower, upper)))
    return told, result


def test_unbounded_belief_synthesis_tells_the_best_bounds_so_far(pomdp):
    told, result = _told(synthesize, pomdp, load_spec("specs/phi1.toml", pomdp.town))
    assert len({run.horizon for run in result.stats.runs}) > 1, "several searches, bounded and not"
    lowers = [lower for lower, _ in told]
    uppers = [upper for _, upper in told]
    assert all(lower is not None for lower in lowers)
    assert lowers == sorted(lowers) and uppers == sorted(uppers, reverse=True), told
    assert max(lowers) > 0.9 and abs(lowers[-1] - result.lower) <= ROUNDING, (told[-1], result.lower)
    assert min(uppers) >= result.upper - ROUNDING, (told, result.upper)


def test_trust_state_synthesis_tells_no_lower_bound_before_a_policy_is_valued(pomdp):
    told, result = _told(synthesize_joint, pomdp, load_spec("specs/phi1_trust.toml", pomdp.town))
    assert result.lower > 0.5
    assert told[0][0] is None, told   # the unbounded U comes first: no policy valued yet
    valued = [lower for lower, _ in told if lower is not None]
    assert valued and valued == sorted(valued) and abs(valued[-1] - result.lower) <= ROUNDING, told
    assert 0.0 not in valued
