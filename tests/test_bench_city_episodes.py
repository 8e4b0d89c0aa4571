"""The city-episodes benchmark drives a spec of the packaged town `city` as the package imports it
now: its start road and waypoints are the town's (a change of the importer's rule, such as the
turn restrictions, dropped its former start road from the town)."""

from __future__ import annotations

from benchmarks import bench_city_episodes as bench
from tests.extras import needs_cities_extra
from trustroute.networks.cities import CITY
from trustroute.networks.town import load_town
from trustroute.policies.routing.free import baseline_route

pytestmark = needs_cities_extra


def test_the_benchmarks_spec_is_a_spec_of_the_packaged_city(tmp_path):
    town = load_town(CITY)
    spec = bench.city_spec(town, tmp_path)   # an InputError where a road or waypoint is not the town's
    # the trust-free route the benchmark's ego drives, from its start road through both waypoints
    route = baseline_route(town, spec)
    assert route[0] == spec.start and len(route) == 22
