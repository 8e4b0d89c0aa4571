"""The warm-up has a route and incidents of its own, drawn (seeded) apart from the trials': it
rehearses no trial. Driven in this process on libsumo with a pipe for the person."""

from __future__ import annotations

import pytest

from trustroute.harness.live.server import warm_up_task
from trustroute.harness.live.warmup import WARM_UP_ROADS, run_warm_up, warm_up_plan
from trustroute.harness.live.worker import LiveOptions, RemoteDriver
from trustroute.harness.study.context import study_context
from trustroute.harness.study.plan import plan_episodes
from trustroute.harness.study.runner import run_planned_episode
from trustroute.networks.road import Road

from .conftest import tiny_config
from .test_live_worker import Pipe

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]


def drive(config, task, warm_up: bool):
    driver = RemoteDriver(Pipe(), (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1e6, client="scripted"),
                          episode_id=task.episode_id)
    run = run_warm_up if warm_up else run_planned_episode
    return run(study_context(config), task, driver=driver, observer=driver.observe, person=driver)


def test_the_warm_up_drives_its_own_drawn_route_and_incidents(tmp_path):
    config = tiny_config(tmp_path, participants=3)
    setup = study_context(config).setup("phi1", "free")
    plans = [warm_up_plan(setup.town, setup.spec.start, config.seed, p) for p in range(3)]
    assert plans[0] == warm_up_plan(setup.town, setup.spec.start, config.seed, 0)   # seeded
    assert len({plan[0] for plan in plans}) == 3 or len({str(plan[1]) for plan in plans}) == 3
    route, incidents = plans[0]
    # the start road and WARM_UP_ROADS roads after it (docs/live_studies.md, "The warm-up")
    assert len(route) == 1 + WARM_UP_ROADS and route[0] == setup.spec.start
    assert set(incidents) == set(route[1:])                            # an incident on each but the start
    steps = zip(route, route[1:], strict=False)
    assert all(setup.town.successor(a, Road.parse(b).to_junction) == b for a, b in steps)
    assert set(incidents.values()) <= set(setup.town.incidents.values())
    task = warm_up_task(config, 0)
    warm_up = drive(config, task, warm_up=True).roads
    assert tuple(warm_up["directed_road"]) == route                    # the drawn route, to its end
    assert dict(zip(warm_up["directed_road"][1:], warm_up["incident"][1:], strict=True)) == incidents
    trial = drive(config, plan_episodes(config)[0], warm_up=False).roads   # the first trial
    assert (tuple(trial["directed_road"]), tuple(trial["incident"])) != (route, tuple(warm_up["incident"]))
    assert warm_up["directed_road"].iloc[0] == trial["directed_road"].iloc[0]   # the same start road


def test_the_warm_up_drives_its_whole_route_whatever_the_trial_spec_says(tmp_path):
    """A first trial's spec that the drawn route satisfies on its way (a waypoint among its roads)
    does not end the warm-up there: it rehearses no trial, so it ends at its route's end."""
    setup = study_context(tiny_config(tmp_path)).setup("phi1", "free")
    route, _ = warm_up_plan(setup.town, setup.spec.start, 1, 0)   # tiny_config's seed, participant 0
    (tmp_path / "early.toml").write_text(f'name = "early"\nstart = "{route[0]}"\nformula = "F v1"\n\n'
                                         f'[states]\nv1 = ["{route[1]}"]\n')
    config = tiny_config(tmp_path, specs=("early.toml",))
    warm_up = drive(config, warm_up_task(config, 0), warm_up=True)
    assert tuple(warm_up.roads["directed_road"]) == route
    assert warm_up.summary["end_reason"] == "destination"
