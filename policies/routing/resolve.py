"""Policy names to policies: "free", "aware" (synthesized once, then cached) or a policy file.

"aware" is `synthesize(pomdp, spec, horizon=AWARE_HORIZON, tau=AWARE_TAU)` with the Bayes filter:
H = 20 junctions because the study measures "policy, then the shortest completion after 20
junctions" (policies.fallback), so maximising P(accepted within 20) is the objective the study
actually scores. It is cached in `cache_dir` under a key made of the content hashes of town,
driver model and spec and these settings; a cache entry is a policy file like any other.
"""

from __future__ import annotations

import contextlib
import hashlib
from pathlib import Path

from trustroute.networks.errors import InputError
from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, build_pomdp
from trustroute.policies.routing.files import load_policy, save_policy
from trustroute.policies.routing.free import trust_free_policy
from trustroute.policies.routing.protocol import RoutingPolicy
from trustroute.policies.synthesis.search import synthesize

AWARE_HORIZON = 20
AWARE_TAU = 1e-3
AWARE_TIME_LIMIT = 120.0
DEFAULT_POLICY_CACHE = Path.home() / ".cache" / "trustroute" / "policies"


def aware_cache_path(town: Town, driver: DriverModel, spec: Spec, cache_dir: str | Path | None,
                     horizon: int | None = AWARE_HORIZON, belief_rule: BeliefRule = "bayes") -> Path:
    """Cache entry of the "aware" policy for these inputs (horizon None: unbounded; cache_dir None:
    DEFAULT_POLICY_CACHE)."""
    key = hashlib.sha256("|".join((town.content_hash, driver.content_hash, spec.content_hash,
                                   f"H={horizon}", f"tau={AWARE_TAU}", belief_rule)).encode())
    return Path(cache_dir or DEFAULT_POLICY_CACHE) / f"aware-{spec.name}-{key.hexdigest()[:16]}.json"


def aware_policy(town: Town, driver: DriverModel, spec: Spec, cache_dir: str | Path | None,
                 horizon: int | None = AWARE_HORIZON, belief_rule: BeliefRule = "bayes",
                 progress: bool = False) -> RoutingPolicy:
    path = aware_cache_path(town, driver, spec, cache_dir, horizon, belief_rule)
    if path.is_file():
        return load_policy(path, town, driver, spec)
    with synthesis_progress(f"synthesizing aware for {spec.name}", progress) as on_iteration:
        result = synthesize(build_pomdp(town, driver), spec, tau=AWARE_TAU, time_limit=AWARE_TIME_LIMIT,
                            horizon=horizon, belief_rule=belief_rule, on_iteration=on_iteration)
    save_policy(result, path, town, driver, spec)
    return result.policy


def resolve_policy(name_or_path: str, town: Town, driver: DriverModel, spec: Spec,
                   cache_dir: str | Path | None = None, horizon: int | None = AWARE_HORIZON,
                   belief_rule: BeliefRule = "bayes", progress: bool = False) -> RoutingPolicy:
    """"free", "aware" or the path of a policy file, as a RoutingPolicy for this town/model/spec.

    horizon: the junction horizon "aware" is synthesized for (default 20; None: unbounded).
    belief_rule: the AV filter "aware" is synthesized for. progress: a progress bar while synthesizing.
    """
    if name_or_path == "free":
        return trust_free_policy(town, spec)
    if name_or_path == "aware":
        return aware_policy(town, driver, spec, cache_dir, horizon, belief_rule, progress)
    if not Path(name_or_path).is_file():
        raise InputError(name_or_path, "", "not a policy file and not 'free' or 'aware'",
                         "pass 'free', 'aware' or the path of a policy file written by trustroute synth")
    return load_policy(name_or_path, town, driver, spec)


@contextlib.contextmanager
def synthesis_progress(description: str, enabled: bool):
    """A tqdm bar of synthesis rounds with the current bounds; yields the `on_iteration` callback."""
    from tqdm import tqdm

    with tqdm(desc=description, unit="round", disable=None if enabled else True, leave=False,
              dynamic_ncols=True) as bar:
        def on_iteration(lower: float, upper: float) -> None:
            bar.update(1)
            bar.set_postfix_str(f"L={lower:.4f} U={upper:.4f}", refresh=False)

        yield on_iteration
