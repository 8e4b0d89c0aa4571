from networks.town import load_town


def test_default_town_shape(town):
    assert len(town.junctions) == 12
    assert len(town.roads) == 18
    assert len(town.states) == 36
    assert all(len(town.neighbours[j]) == 3 for j in town.junctions)


def test_actions_exclude_u_turns(town):
    for state in town.states:
        came_from, at = state.split("-")
        actions = town.actions(state)
        assert came_from not in actions
        assert set(actions) == set(town.neighbours[at]) - {came_from}


def test_content_hash_ignores_formatting(tmp_path, town):
    import json
    data = json.loads(open(town.source_path if town.source_path != "default town" else
                           __import__("networks.town").town.DEFAULT_TOWN_PATH).read())
    (tmp_path / "t.json").write_text(json.dumps(data, indent=None))
    assert load_town(tmp_path / "t.json").content_hash == town.content_hash


def test_shortest_route_reaches_target(town):
    route = town.shortest_route("E-A", {"B-G", "F-G", "I-G"})
    assert route[0] == "E-A" and route[-1] in {"B-G", "F-G", "I-G"}
    for a, b in zip(route, route[1:], strict=False):
        assert b in town.successors(a)
