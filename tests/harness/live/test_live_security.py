"""Who may do what on a live study, and what bad input does: nothing, but an error reply."""

from __future__ import annotations

import asyncio
import hashlib
import json
import os
import secrets
import time
from html import escape

import pytest
from fastapi.testclient import TestClient
from pydantic import TypeAdapter
from starlette.websockets import WebSocketDisconnect

from trustroute.core.errors import InputError
from trustroute.harness.live.app import (
    CONSOLE_EXPIRED,
    CONSOLE_HERE,
    CONSOLE_REFUSED,
    POLICY_VIOLATION,
    STATION_HERE,
    live_app,
)
from trustroute.harness.live.auth import (
    CONSOLE_IDLE_SECONDS,
    EXPERIMENTER_COOKIE,
    MAX_TOKEN_CHARS,
    PARTICIPANT_COOKIE,
)
from trustroute.harness.live.protocol import (
    BURST,
    MAX_BODY_BYTES,
    MAX_MESSAGE_BYTES,
    MessageError,
    error_reply,
    parse_client_message,
)
from trustroute.harness.live.server import LiveStudy, ServerOptions
from trustroute.harness.study.config import load_study_config

from .conftest import tiny_config


def bearer(token: str) -> dict:
    return {"Authorization": f"Bearer {token}"}


@pytest.fixture
def client(live_study):
    with TestClient(live_app(live_study)) as test_client:
        yield test_client


def create(client, study, label: str = "") -> str:
    headers = bearer(study.experimenter_token)
    response = client.post("/api/participants", json={"label": label}, headers=headers)
    assert response.status_code == 200, response.text
    return response.json()["token"]


def test_a_foreign_token_is_refused(client, live_study):
    first, second = create(client, live_study, "one"), create(client, live_study, "two")
    foreign = secrets.token_urlsafe(32)
    assert client.get("/api/participants").status_code == 401
    for token in (foreign, first):   # neither a stranger nor a participant reaches the console's API
        headers = bearer(token)
        assert client.get("/api/participants", headers=headers).status_code == 403
        assert client.get("/api/files", headers=headers).status_code == 403
        assert client.get("/api/download/study.json", headers=headers).status_code == 403
        assert client.post("/api/participants", json={}, headers=headers).status_code == 403
        assert client.post("/api/participants/0/control", json={"action": "pause"},
                           headers=headers).status_code == 403
    # a participant reads their own session only
    assert client.get("/api/participants/0", headers=bearer(first)).status_code == 200
    assert client.get("/api/participants/1", headers=bearer(first)).status_code == 403
    assert client.get("/api/participants/0", headers=bearer(second)).status_code == 403
    assert client.get("/api/me", headers=bearer(foreign)).status_code == 403
    assert client.get("/api/me", headers=bearer(second)).json()["participant"] == 1
    assert client.post("/api/claim", json={"token": foreign}).status_code == 403
    assert client.get(f"/login?token={foreign}", follow_redirects=False).status_code == 403
    with pytest.raises(WebSocketDisconnect) as closed:
        with client.websocket_connect("/ws", headers=bearer(foreign)):
            pass
    assert closed.value.code == POLICY_VIOLATION
    # the websocket acts on the session the token names
    with client.websocket_connect("/ws", headers=bearer(second)) as socket:
        assert socket.receive_json()["participant"] == 1


def test_links_set_httponly_cookies_that_authenticate_and_spend_the_link(client, live_study):
    token = create(client, live_study)
    page = client.get(f"/p/{token}", follow_redirects=False)   # the page only: a preview spends nothing
    assert page.status_code == 200 and "/static/link.js" in page.text and token not in page.text
    response = client.post("/api/claim", json={"token": token})
    assert response.status_code == 200 and response.json()["next"] == "/station"
    cookie = response.headers["set-cookie"]
    assert "HttpOnly" in cookie and "samesite=strict" in cookie.lower() and "secure" not in cookie.lower()
    assert token not in cookie   # a fresh token: the one in the link (and the browser's history) is spent
    assert client.get("/api/me").json()["participant"] == 0   # the cookie alone now authenticates
    assert client.post("/api/claim", json={"token": token}).status_code == 403
    assert client.get("/api/me", headers=bearer(token)).status_code == 403
    log = (live_study.study_dir / "live" / "tokens.jsonl").read_text().splitlines()
    assert [json.loads(line)["participant"] for line in log] == [0]
    client.cookies.clear()   # another browser: this one is the participant's (one role a browser)
    login = client.get(f"/login?token={live_study.login_token}", follow_redirects=False)
    assert login.status_code == 303 and "HttpOnly" in login.headers["set-cookie"]
    assert client.get("/api/participants").status_code == 200


def test_the_console_link_works_once_and_its_cookie_holds_a_fresh_token(client, live_study):
    """Like a participant's link, the console link's token is exchanged for a fresh one that only
    the cookie holds: the link in the browser's history (or a proxy's log) is spent. The
    experimenter token, for scripts, opens no console by address; with it a new link is made."""
    printed, experimenter = live_study.login_token, live_study.experimenter_token
    login = client.get(f"/login?token={printed}", follow_redirects=False)
    assert login.status_code == 303 and login.headers["location"] == "/console"
    cookie = login.headers["set-cookie"]
    assert printed not in cookie and experimenter not in cookie and "HttpOnly" in cookie
    assert client.get("/console").status_code == 200   # the cookie's fresh token
    assert client.get(f"/login?token={printed}", follow_redirects=False).status_code == 403   # spent
    assert client.get(f"/login?token={experimenter}", follow_redirects=False).status_code == 403
    participant = create(client, live_study)
    assert client.post("/api/login-link", headers=bearer(participant)).status_code == 403
    link = client.post("/api/login-link", headers=bearer(experimenter)).json()["link"]
    client.cookies.clear()
    assert client.get("/console").status_code == 401
    assert client.get(link, follow_redirects=False).status_code == 303
    assert client.get("/api/participants").status_code == 200
    assert client.get(link, follow_redirects=False).status_code == 403
    assert client.get("/api/participants", headers=bearer(experimenter)).status_code == 200   # scripts


def test_a_console_login_unused_for_its_idle_time_expires(client, live_study):
    """A console session's cookie unused for CONSOLE_IDLE_SECONDS is refused, saying how to log in
    again; each use starts its idle time again; the experimenter token (scripts) does not expire."""
    now = [1000.0]
    live_study.credentials.clock = lambda: now[0]
    assert client.get(f"/login?token={live_study.login_token}", follow_redirects=False).status_code == 303
    for _ in range(2):   # used within its idle time, twice: in use for longer than one idle time
        now[0] += CONSOLE_IDLE_SECONDS - 1
        assert client.get("/api/participants").status_code == 200
    now[0] += CONSOLE_IDLE_SECONDS
    expired = client.get("/api/participants")
    assert expired.status_code == 401 and expired.json()["detail"]["detail"] == CONSOLE_EXPIRED
    assert "12 hours" in CONSOLE_EXPIRED and "log in again from a console link" in CONSOLE_EXPIRED
    assert client.post("/api/participants", json={}).status_code == 401
    page = client.get("/console", headers={"Accept": "text/html"})
    assert page.status_code == 401 and escape(CONSOLE_REFUSED) in page.text and "expired" in CONSOLE_REFUSED
    experimenter = bearer(live_study.experimenter_token)
    assert client.get("/api/participants", headers=experimenter).status_code == 200
    link = client.post("/api/login-link", headers=experimenter).json()["link"]
    assert client.get(link, follow_redirects=False).status_code == 303   # logged in again
    assert client.get("/api/participants").status_code == 200 and live_study.sessions == {}


def test_a_browser_holds_one_role_the_console_or_a_participants_session(client, live_study):
    """Whoever sits at a browser logged in to the console could open it: a participant's link is
    not claimed there, nor is a console link where a participant's session is open. A refused link
    is not spent: it works in another browser."""
    token = create(client, live_study)
    assert client.get(f"/login?token={live_study.login_token}", follow_redirects=False).status_code == 303
    refused = client.post("/api/claim", json={"token": token})
    assert refused.status_code == 409 and refused.json()["detail"]["detail"] == CONSOLE_HERE
    assert client.get("/api/me").status_code == 403
    link = client.post("/api/login-link").json()["link"]
    with TestClient(live_app(live_study)) as station, TestClient(live_app(live_study)) as other:
        assert station.post("/api/claim", json={"token": token}).status_code == 200   # the link unspent
        assert station.get(link, follow_redirects=False).status_code == 409
        page = station.get(link, headers={"Accept": "text/html"}, follow_redirects=False)
        assert page.status_code == 409 and escape(STATION_HERE) in page.text
        assert station.get("/console").status_code == 401
        assert other.get(link, follow_redirects=False).status_code == 303   # the console link unspent
        assert other.get("/api/participants").status_code == 200


def test_secure_cookies_for_studies_served_over_https(tmp_path):
    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions(secure_cookies=True)).open()
    try:
        with TestClient(live_app(study)) as client:
            response = client.get(f"/login?token={study.login_token}", follow_redirects=False)
            assert "secure" in response.headers["set-cookie"].lower()
    finally:
        study.close()


def test_an_over_long_token_is_refused_before_it_is_hashed(client, live_study, monkeypatch):
    """A token longer than MAX_TOKEN_CHARS is no token of ours, wherever it is presented: it is
    refused without being hashed (a megabyte-long header costs no hashing)."""
    sha256, hashed = hashlib.sha256, []
    long = "A" * (MAX_TOKEN_CHARS + 1)

    def counting(data=b"", *args, **kwargs):
        hashed.extend([data] if long.encode()[:MAX_TOKEN_CHARS] in bytes(data) else [])
        return sha256(data, *args, **kwargs)

    monkeypatch.setattr(hashlib, "sha256", counting)
    for path in ("/api/me", "/api/participants", "/console", "/station", "/api/net"):
        assert client.get(path, headers=bearer(long)).status_code in (401, 403), path
    for cookie in (PARTICIPANT_COOKIE, EXPERIMENTER_COOKIE):
        client.cookies.set(cookie, long)
        assert client.get("/api/me").status_code == 403 and client.get("/console").status_code in (401, 403)
        client.cookies.clear()
    assert client.get(f"/login?token={long}", follow_redirects=False).status_code == 403
    assert client.post("/api/claim", json={"token": long}).status_code == 422
    with pytest.raises(WebSocketDisconnect) as closed:
        with client.websocket_connect("/ws", headers=bearer(long)):
            pass
    assert closed.value.code == POLICY_VIOLATION
    assert hashed == []
    assert client.get("/api/me", headers=bearer(long[:MAX_TOKEN_CHARS])).status_code == 403
    assert hashed   # one at the cap is looked up (hashed): the counting sees it


def test_tokens_are_stored_only_as_digests(client, live_study):
    token = create(client, live_study)
    registry = live_study.registry_path().read_text()
    assert token not in registry and live_study.experimenter_token not in registry
    assert len(token) >= 40


def test_a_path_traversal_download_is_refused(client, live_study, tmp_path):
    headers = bearer(live_study.experimenter_token)
    ok = client.get("/api/download/study.json", headers=headers)
    assert ok.status_code == 200 and ok.content == (live_study.study_dir / "study.json").read_bytes()
    secret = tmp_path / "secret.txt"
    secret.write_text("outside")
    os.symlink(secret, live_study.study_dir / "leak.txt")                        # a symlink out
    os.symlink(live_study.study_dir / "study.json", live_study.study_dir / "alias.json")  # and one within
    for path in ("..%2Fsecret.txt", "%2e%2e/secret.txt", "parts/..%2F..%2Fsecret.txt", "%2Fetc%2Fpasswd",
                 "leak.txt", "alias.json", "parts", "nothing.json", "study.json%00.txt"):
        response = client.get(f"/api/download/{path}", headers=headers)
        assert response.status_code == 404, path
        assert b"outside" not in response.content
    for relative in ("../secret.txt", "/etc/passwd", "leak.txt", "alias.json", "parts/../../x",
                     "a\\..\\b", ""):
        with pytest.raises(ValueError):
            live_study.download_path(relative)
    assert "leak.txt" not in client.get("/api/files", headers=headers).json()["files"]


def state_of(client, study) -> dict:
    return client.get("/api/participants", headers=bearer(study.experimenter_token)).json()


def control(**fields) -> str:
    return json.dumps({"type": "control", "steer": 0, "throttle": 0, "brake": 0} | fields)


def test_malformed_oversized_and_out_of_order_messages_get_errors_and_change_nothing(client, live_study):
    token = create(client, live_study)
    before, registry = state_of(client, live_study), live_study.registry_path().read_bytes()
    with client.websocket_connect("/ws", headers=bearer(token)) as socket:
        assert socket.receive_json()["type"] == "welcome"
        assert socket.receive_json()["phase"] == "consent"
        cases = [("not json", "malformed"), ('{"type": "trust", "value": 9}', "malformed"),
                 ('{"type": "trust", "value": "5"}', "malformed"), ('{"type": "warp"}', "malformed"),
                 ('{"type": "consent", "agree": true, "admin": true}', "malformed"),
                 ('{"type": "consent", "agree": "no"}', "malformed"), ('{"type": "consent"}', "malformed"),
                 (json.dumps({"type": "ping", "pad": "x" * MAX_MESSAGE_BYTES}), "oversized"),
                 ('{"type": "takeover"}', "out_of_order"), ('{"type": "hand_back"}', "out_of_order"),
                 ('{"type": "start"}', "out_of_order"), ('{"type": "trust", "value": 4}', "out_of_order"),
                 ('{"type": "resume"}', "out_of_order"), ('{"type": "pass"}', "out_of_order"),
                 ('{"type": "consent", "agree": true, "lockstep": true}', "malformed"),
                 (control(source="wheel", steer=2), "malformed"),
                 ('{"type": "control", "source": "wheel", "steer": 0, "throttle": 0.5}', "malformed"),
                 ('{"type": "control", "steer": 0, "throttle": 0, "brake": 0}', "malformed"),   # no source
                 (control(source="mouse"), "malformed"), (control(source="wheel"), "out_of_order")]
        for raw, code in cases:
            socket.send_text(raw)
            reply = socket.receive_json()
            assert (reply["type"], reply["code"]) == ("error", code), raw
        socket.send_bytes(b"\xff\xfe")
        assert socket.receive_json()["code"] == "malformed"
    assert state_of(client, live_study) == before
    assert live_study.registry_path().read_bytes() == registry
    assert not (live_study.study_dir / "parts").exists()


def test_a_key_given_twice_or_a_binary_frame_is_malformed(client, live_study):
    """A message naming a key twice is refused, not read by its last value; a message is JSON
    text, so a binary frame is refused whatever it holds."""
    token = create(client, live_study)
    before = state_of(client, live_study)
    with client.websocket_connect("/ws", headers=bearer(token)) as socket:
        socket.receive_json(), socket.receive_json()
        for raw in ('{"type": "ping", "type": "consent", "agree": true}',
                    '{"type": "consent", "agree": true, "client": "station", "client": "scripted"}',
                    "[" * 2000):
            socket.send_text(raw)
            reply = socket.receive_json()
            assert (reply["type"], reply["code"]) == ("error", "malformed"), raw
        socket.send_bytes(b'{"type": "consent", "agree": true}')
        reply = socket.receive_json()
        assert reply["code"] == "malformed" and "binary" in reply["detail"]
        socket.send_text('{"type": "ping"}')
        assert socket.receive_json() == {"type": "pong"}
    assert state_of(client, live_study) == before


def test_a_flood_is_rate_limited_and_changes_nothing(client, live_study):
    token = create(client, live_study)
    before = state_of(client, live_study)
    with client.websocket_connect("/ws", headers=bearer(token)) as socket:
        socket.receive_json(), socket.receive_json()
        flood = 3 * BURST
        for _ in range(flood):
            socket.send_text('{"type": "takeover"}')
        replies = [socket.receive_json() for _ in range(flood)]
        codes = [reply.get("code") for reply in replies]
        assert codes.count("rate_limited") >= flood - BURST - 5
        assert set(codes) <= {"rate_limited", "out_of_order"}
        # a wheel's controls count in a bucket of their own: they never starve the other messages
        control = '{"type": "control", "source": "keyboard", "steer": 0, "throttle": 0, "brake": 0}'
        for _ in range(5):
            socket.send_text(control)
            assert socket.receive_json()["code"] == "out_of_order"   # not driving, and not a wheel study
        time.sleep(0.5)   # the bucket refills: the connection is usable again
        socket.send_text('{"type": "ping"}')
        assert socket.receive_json() == {"type": "pong"}
    assert state_of(client, live_study) == before


def test_bad_http_bodies_get_errors_and_change_nothing(client, live_study):
    headers = bearer(live_study.experimenter_token)
    create(client, live_study)
    before = state_of(client, live_study)
    big = client.post("/api/participants", content=json.dumps({"label": "x" * MAX_BODY_BYTES}),
                      headers={**headers, "content-type": "application/json"})
    assert big.status_code == 413 and big.json()["code"] == "oversized"
    for body in ("{", '{"label": 5}', '{"label": "a", "admin": true}', '{"label": "<script>"}',
                 '{"label": "a", "label": "b"}', "[" * 10_000):
        response = client.post("/api/participants", content=body,
                               headers={**headers, "content-type": "application/json"})
        assert response.status_code == 422 and response.json()["code"] == "malformed", body
    assert client.post("/api/participants/0/control", json={"action": "explode"},
                       headers=headers).status_code == 422
    response = client.post("/api/participants/0/control", json={"action": "pause"}, headers=headers)
    assert response.status_code == 409 and response.json()["detail"]["code"] == "out_of_order"
    unknown = client.post("/api/participants/7/control", json={"action": "pause"}, headers=headers)
    assert unknown.status_code == 404
    assert state_of(client, live_study) == before


def test_a_withdrawal_is_confirmed_by_true_and_nothing_else(client, live_study):
    """A withdrawal deletes data: its `confirm` is the JSON `true`; 1, 1.0 or "true" (which a
    literal True would take as equal) are malformed and withdraw no one."""
    headers = bearer(live_study.experimenter_token)
    create(client, live_study)
    for confirm in ("1", "1.0", '"true"', "false", "null"):
        response = client.post("/api/participants/0/withdraw", content=f'{{"confirm": {confirm}}}',
                               headers={**headers, "content-type": "application/json"})
        assert response.status_code == 422 and response.json()["code"] == "malformed", confirm
        assert live_study.sessions[0].phase == "consent" and 0 in live_study.credentials.participants
    response = client.post("/api/participants/0/withdraw", json={"confirm": True}, headers=headers)
    assert response.status_code == 200 and live_study.sessions[0].phase == "withdrawn"


@pytest.mark.parametrize("body", [b'{"label": "\xff"}', b'{"label": ' + b"9" * 5000 + b"}",
                                  '{"label": "a"}'.encode("utf-16")])
def test_a_body_the_json_parser_cannot_read_is_malformed_in_the_protocols_form(client, live_study, body):
    """Bytes that are no UTF-8, or an integer longer than Python reads, are refused as any other
    body that is no JSON: 422 `malformed`, the protocol's error."""
    response = client.post("/api/participants", content=body, headers={
        **bearer(live_study.experimenter_token), "content-type": "application/json"})
    assert response.status_code == 422 and response.json()["code"] == "malformed", response.text
    assert live_study.sessions == {}


def test_a_body_is_parsed_once(client, live_study, monkeypatch):
    """The guard parses a JSON body (refusing a key given twice) and the route validates what it
    parsed: the body's text is read by the JSON parser once."""
    loads, parsed = json.loads, []
    body = '{"label": "parsed once"}'

    def counting(text, *args, **kwargs):
        parsed.extend([text] if text in (body, body.encode()) else [])
        return loads(text, *args, **kwargs)

    monkeypatch.setattr(json, "loads", counting)
    response = client.post("/api/participants", content=body, headers={
        **bearer(live_study.experimenter_token), "content-type": "application/json"})
    assert response.status_code == 200 and live_study.sessions[0].label == "parsed once"
    assert len(parsed) == 1


def test_a_message_is_parsed_once(client, live_study, monkeypatch):
    """A websocket message's text is read by one JSON parser once (protocol.json_value, which
    refuses a key given twice) and the value validated: neither pydantic's JSON mode nor a second
    `json.loads` reads it again."""
    loads, validate_json, parsed = json.loads, TypeAdapter.validate_json, []
    message = '{"type": "ping"}'

    def counting_loads(text, *args, **kwargs):
        parsed.extend([text] if text == message else [])
        return loads(text, *args, **kwargs)

    def counting_validate_json(adapter, data, *args, **kwargs):
        parsed.extend([data] if data == message else [])
        return validate_json(adapter, data, *args, **kwargs)

    monkeypatch.setattr(json, "loads", counting_loads)
    monkeypatch.setattr(TypeAdapter, "validate_json", counting_validate_json)
    token = create(client, live_study)
    with client.websocket_connect("/ws", headers=bearer(token)) as socket:
        socket.receive_json(), socket.receive_json()
        socket.send_text(message)
        assert socket.receive_json() == {"type": "pong"}
    assert len(parsed) == 1


@pytest.mark.parametrize("number", ["NaN", "Infinity", "-Infinity", "1e400", "-1e400"])
def test_a_number_that_is_not_finite_is_malformed_wherever_a_message_has_a_number(number):
    """NaN, Infinity and 1e400 (beyond a float's range: infinite) read as floats; every number field
    of the messages refuses them."""
    steer = control(source="keyboard").replace('"steer": 0', f'"steer": {number}')
    for raw in (f'{{"type": "shown", "t": {number}}}', steer, f'{{"type": "trust", "value": {number}}}',
                f'{{"type": "trust", "value": 4, "prompt": {{"episode_id": "e", "road": {number}}}}}'):
        with pytest.raises(MessageError) as info:
            parse_client_message(raw)
        assert info.value.reply["code"] == "malformed", raw


def test_a_message_nested_too_deeply_is_malformed():
    for raw in ("[" * 2000, '{"type": "ping", "x": ' + "[" * 1500 + "]" * 1500 + "}"):
        with pytest.raises(MessageError) as info:
            parse_client_message(raw)
        assert info.value.reply == error_reply("malformed", "the message is nested too deeply")


def test_a_body_is_counted_as_it_is_received(live_study):
    """Whatever the headers say, reading a body stops once it passes MAX_BODY_BYTES: 413."""
    chunk, pulled, sent = 1024, [], []

    async def receive() -> dict:
        pulled.append(chunk)
        return {"type": "http.request", "body": b"a" * chunk, "more_body": len(pulled) < 1024}

    async def send(message: dict) -> None:
        sent.append(message)

    headers = [(b"host", b"testserver"), (b"content-type", b"application/json"), (b"content-length", b"2")]
    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "POST",
             "scheme": "http", "path": "/api/claim", "raw_path": b"/api/claim", "root_path": "",
             "query_string": b"", "headers": headers, "client": ("127.0.0.1", 1),
             "server": ("testserver", 80)}
    asyncio.run(live_app(live_study)(scope, receive, send))
    assert sent[0]["status"] == 413 and json.loads(sent[1]["body"])["code"] == "oversized"
    assert sum(pulled) <= MAX_BODY_BYTES + chunk


def test_all_planned_participants_then_no_more(client, live_study):
    create(client, live_study), create(client, live_study)
    response = client.post("/api/participants", json={}, headers=bearer(live_study.experimenter_token))
    assert response.status_code == 409
    assert len(state_of(client, live_study)["participants"]) == 2


def test_two_servers_on_one_study_directory_are_refused(live_study, tmp_path):
    second = LiveStudy(live_study.config, live_study.study_dir, ServerOptions())
    with pytest.raises(InputError, match="in use"):
        second.open()


def test_a_config_of_another_engine_is_refused(tmp_path):
    config = tiny_config(tmp_path).with_overrides(engine="sumo")
    with pytest.raises(InputError, match="live"):
        LiveStudy(config, tmp_path / "study")


def test_trustroute_study_refuses_a_live_config(tmp_path):
    from trustroute.harness.study.runner import run_and_consolidate

    with pytest.raises(InputError, match="trustroute live"):
        run_and_consolidate(tiny_config(tmp_path), tmp_path / "study", 1, None, progress=False)
    assert not (tmp_path / "study").exists()


def test_the_pages_need_their_token_and_carry_the_security_headers(client, live_study):
    token = create(client, live_study)
    assert client.get("/console").status_code == 401
    assert client.get("/console", headers=bearer(token)).status_code == 403
    assert client.get("/station").status_code == 403
    # a browser's navigation is told what to do in a page; any other client gets the JSON refusal
    for path, says in (("/station", "link the experimenter gave you"), ("/console", "new console link"),
                       ("/login?token=spent", "new console link")):
        page = client.get(path, headers={"Accept": "text/html,application/xhtml+xml,*/*;q=0.8"})
        assert page.status_code in (401, 403) and page.headers["content-type"].startswith("text/html")
        assert says in page.text and "{" not in page.text
        assert client.get(path).json()["detail"]["code"] == "forbidden"
    assert client.get("/station", headers=bearer(secrets.token_urlsafe(32))).status_code == 403
    console = client.get("/console", headers=bearer(live_study.experimenter_token))
    station = client.get("/station", headers=bearer(token))
    assert console.status_code == station.status_code == 200
    assert "experimenter console" in console.text and "/static/station.js" in station.text
    for name in ("live.css", "console.js", "station.js", "driver_view.js", "map_view.js", "inputs.js",
                 "next_turn.js", "vendor/three.module.js", "vendor/three.core.js"):
        assert client.get(f"/static/{name}").status_code == 200
    for name in ("..%2Fserver.py", "app.py", "console.html", "vendor/three.LICENSE", "vendor/../app.py"):
        assert client.get(f"/static/{name}").status_code == 404
    for response in (console, station, client.get("/api/participants")):
        assert response.headers["x-frame-options"] == "DENY"
        assert response.headers["referrer-policy"] == "no-referrer"
        assert "default-src 'self'" in response.headers["content-security-policy"]
        assert "unsafe-inline" not in response.headers["content-security-policy"]


def test_the_net_view_is_for_participants_and_the_experimenter(client, live_study):
    token = create(client, live_study)
    assert client.get("/api/net").status_code == 403
    assert client.get("/api/net", headers=bearer(secrets.token_urlsafe(32))).status_code == 403
    view = client.get("/api/net", headers=bearer(token)).json()
    assert client.get("/api/net", headers=bearer(live_study.experimenter_token)).json() == view
    roads = {lane["id"].rsplit("_", 1)[0] for lane in view["lanes"] if not lane["internal"]}
    assert {"E-A", "A-B"} <= roads and all(len(lane["shape"]) >= 2 for lane in view["lanes"])
    assert {"A", "B", "E"} <= set(view["junctions"])


def test_a_control_from_an_input_the_study_does_not_allow_is_refused(tmp_path):
    """`[live] inputs = ["wheel"]`: the welcome names the inputs, and in a trial a keyboard's
    control is refused for its input, before anything else is asked of it (a wheel's, sent while
    the autopilot drives, is refused only for the mode)."""
    tiny_config(tmp_path, participants=1)
    path = tmp_path / "live.toml"
    path.write_text(path.read_text() + '\n[live]\ndriving = "continuous"\ninputs = ["wheel"]\n')
    options = ServerOptions(pace=1.0, warm_up=False)
    study = LiveStudy(load_study_config(path), tmp_path / "study", options).open()
    try:
        with TestClient(live_app(study)) as client, \
                client.websocket_connect("/ws", headers=bearer(create(client, study))) as socket:
            welcome = socket.receive_json()
            assert (welcome["driving"], welcome["inputs"]) == ("continuous", ["wheel"])
            socket.send_json({"type": "consent", "agree": True})
            socket.send_json({"type": "start", "trust": 4})
            while (message := socket.receive_json()).get("type") != "state" or message["phase"] != "driving":
                pass
            for source, detail in (("keyboard", "does not allow driving by keyboard"),
                                   ("gamepad", "does not allow driving by gamepad"),
                                   ("wheel", "while the mode is auto")):
                socket.send_json({"type": "control", "source": source, "steer": 0, "throttle": 0, "brake": 0})
                while (reply := socket.receive_json())["type"] != "error":
                    pass
                assert reply["code"] == "out_of_order" and detail in reply["detail"], reply
    finally:
        study.close()
