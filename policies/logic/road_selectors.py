"""Road selectors of a spec's `[states]` table: `{junction = "J12"}` (every directed road into
the junction) or `{street = "Main Street"}` (every road one of whose street names it is), a name or
a list of names, resolved by a town (networks/road_lookup.py; docs/formats/spec.md, "Waypoint sets
by junction or street")."""

from __future__ import annotations

from trustroute.core.errors import InputError
from trustroute.networks.road_lookup import roads_into, roads_on_street, unknown_road_fix
from trustroute.networks.town import Town

STATE_SELECTOR_KEYS = ("junction", "street")
# a spec written for an imported town, checked against another (the default one, without a town):
# the spec is read alike by the commands (--town), the API (town) and a study (its config's key)
OTHER_TOWN_FIX = "pass the town the spec is written for (--town; in a study config, town in [study])"
SELECTOR_EXAMPLE = 'write v1 = {junction = "J12"} or v1 = {street = "Main Street"} (or a list of names)'


def other_town_fix(fix: str) -> str:
    """The fix for a name of a spec's (a road, junction or street) the town lacks: the town the
    spec is written for first, then `fix`, a name of this town."""
    return f"{OTHER_TOWN_FIX}, or {fix}"


def unknown_spec_road_fix(town: Town, road: str) -> str:
    """The fix for a directed road of a spec's (its start, a road of a waypoint set or of a trust
    state) that `town` lacks: the town the spec is written for, or the roads of this town
    `unknown_road_fix` names."""
    return other_town_fix(unknown_road_fix(town, road))


def _selector_names(entry: dict, atom: str, place: str, source: str) -> tuple[str, list[str]]:
    """(`junction` or `street`, the names it lists) of a road selector `{junction = "J12"}`."""
    keys_given = sorted(entry)
    if len(keys_given) != 1 or keys_given[0] not in STATE_SELECTOR_KEYS:
        raise InputError(source, place, f"state atom '{atom}': a road selector has exactly one key, "
                         f"junction or street (found {', '.join(keys_given) or 'none'})", SELECTOR_EXAMPLE)
    key = keys_given[0]
    value = entry[key]
    names = [value] if isinstance(value, str) else value
    if not (isinstance(names, list) and names and all(isinstance(n, str) and n.strip() for n in names)):
        raise InputError(source, place, f"state atom '{atom}': {key} must be a name or a non-empty list "
                         "of names", SELECTOR_EXAMPLE)
    return key, names


def selected_roads(entry: dict, atom: str, place: str, source: str, town: Town | None) -> list[str]:
    """The directed roads a selector names: every road into each junction, or every road one of
    whose street names is each street (networks/road_lookup.py)."""
    key, names = _selector_names(entry, atom, place, source)
    if town is None:
        raise InputError(source, place, f"state atom '{atom}' names its roads by {key}, which only a "
                         "town can resolve", "check the spec against a town (--town FILE)")
    town_name = town.source_path or "given town"
    roads: set[str] = set()
    for name in names:
        if key == "junction":
            if name not in town.junctions:
                raise InputError(source, place, f"state atom '{atom}': '{name}' is not a junction of the "
                                 f"town ({town_name})", other_town_fix(
                                     "use a junction of the town (trustroute town roads TOWN --near X Y "
                                     "lists the roads near a point)"))
            roads |= roads_into(town, name)
        else:
            found = roads_on_street(town, name)
            if not found:
                raise InputError(source, place, f"state atom '{atom}': no road of the town ({town_name}) "
                                 f"is on a street named '{name}'", other_town_fix(
                                     "use a street name the town's geometry gives (trustroute town "
                                     "roads TOWN --street NAME)"))
            roads |= found
    return sorted(roads)
