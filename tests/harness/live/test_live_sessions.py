"""A participant's session belongs to one browser: pages of other origins are refused, a second
window takes the session over (both are told), connections per participant are limited, and
idle or slow connections are closed; the server's port is taken before anything is printed."""

from __future__ import annotations

import asyncio
import errno
import json
import logging
import resource
import socket
import time

import httpx
import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect as connect_socket

from tests.cli import assert_one_line_error, run_cli
from trustroute.harness.live import scripted
from trustroute.harness.live.app import (
    IDLE,
    POLICY_VIOLATION,
    REPLACED,
    TRY_AGAIN_LATER,
    live_app,
)
from trustroute.harness.live.guard import (
    CONNECTIONS_PER_PARTICIPANT,
    CONNECTIONS_SPARE,
    OPEN_BURST,
    ConnectionGate,
    bind,
    connection_cap,
    own_origins,
    quiet_accept_errors,
)
from trustroute.harness.live.protocol import MessageError, parse_client_message
from trustroute.harness.live.server import LiveStudy, ServerOptions

from .conftest import live_server_of, serving, tiny_config
from .test_live_cli import write_config

OWN = "http://testserver"


def bearer(token: str) -> dict:
    return {"Authorization": f"Bearer {token}"}


@pytest.fixture
def client(live_study):
    with TestClient(live_app(live_study, frozenset({OWN}))) as test_client:
        yield test_client


def new_participant(client, study) -> str:
    response = client.post("/api/participants", json={}, headers=bearer(study.experimenter_token))
    assert response.status_code == 200, response.text
    return response.json()["token"]


def test_a_page_of_another_origin_can_neither_open_the_socket_nor_post(client, live_study):
    token = new_participant(client, live_study)
    for foreign in ("http://127.0.0.1:9999", "http://testserver.evil.example", "null"):
        with pytest.raises(WebSocketDisconnect) as closed:
            with client.websocket_connect("/ws", headers={**bearer(token), "Origin": foreign}):
                pass
        assert closed.value.code == POLICY_VIOLATION, foreign
        headers = {**bearer(live_study.experimenter_token), "Origin": foreign}
        refused = client.post("/api/participants", json={}, headers=headers)
        assert refused.status_code == 403 and refused.json()["detail"]["code"] == "forbidden"
        claim = client.post("/api/claim", json={"token": token}, headers={"Origin": foreign})
        assert claim.status_code == 403
    assert len(live_study.sessions) == 1   # nothing changed
    with client.websocket_connect("/ws", headers={**bearer(token), "Origin": OWN}) as own:
        assert own.receive_json()["type"] == "welcome"
    headers = {**bearer(live_study.experimenter_token), "Origin": OWN}
    ok = client.post("/api/participants", json={}, headers=headers)
    assert ok.status_code == 200


def test_the_own_origins_are_the_bound_addresses_and_the_public_ones(tmp_path):
    loopback = own_origins("127.0.0.1", 8765)
    assert {"http://127.0.0.1:8765", "http://localhost:8765"} <= loopback
    assert "http://127.0.0.1:8766" not in loopback
    assert own_origins("192.0.2.7", 80) == {"http://192.0.2.7"}
    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study",
                      ServerOptions(public_origins=("https://Study.Example.org/",))).open()
    try:
        app = live_app(study, loopback)
        assert "https://study.example.org" in app.state.origins
    finally:
        study.close()


def test_a_second_window_takes_the_session_over_and_both_are_told(client, live_study):
    token = new_participant(client, live_study)
    with client.websocket_connect("/ws", headers=bearer(token)) as first:
        assert [first.receive_json()["type"] for _ in range(2)] == ["welcome", "state"]
        with client.websocket_connect("/ws", headers=bearer(token)) as second:
            replaced = first.receive_json()
            assert replaced["type"] == "replaced" and "another window" in replaced["detail"]
            with pytest.raises(WebSocketDisconnect) as closed:
                first.receive_json()
            assert closed.value.code == REPLACED
            kinds = [second.receive_json() for _ in range(3)]
            assert [message["type"] for message in kinds] == ["welcome", "notice", "state"]
            assert kinds[1]["kind"] == "replaced"
            second.send_json({"type": "ping"})   # the session is the second window's
            assert second.receive_json() == {"type": "pong"}
    assert live_study.sessions[0].push is None


def test_connections_per_participant_are_limited(client, live_study):
    token = new_participant(client, live_study)
    client.app.state.gate = ConnectionGate(rate=1e-6)   # the burst only: no refill on a slow machine
    codes = []
    for _ in range(OPEN_BURST + 4):   # a flood of connections, one after the other
        try:
            with client.websocket_connect("/ws", headers=bearer(token)) as socket_:
                socket_.receive_json()
                codes.append("open")
        except WebSocketDisconnect as closed:
            codes.append(closed.code)
    assert codes[:OPEN_BURST] == ["open"] * OPEN_BURST
    assert codes[OPEN_BURST:] == [TRY_AGAIN_LATER] * 4
    gate = ConnectionGate()   # at most two open at once (the live one and the one replacing it)
    assert [gate.admit(0), gate.admit(0), gate.admit(0), gate.admit(1)] == [True, True, False, True]
    gate.release(0)
    assert gate.admit(0)


@pytest.mark.wallclock
def test_a_silent_socket_is_closed(tmp_path):
    """On the real server, every wait bounded: a socket left open past its idle time fails the
    test rather than hanging it."""
    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions(idle_seconds=0.3)).open()
    try:
        with serving(study) as (address, port):
            token = httpx.post(f"http://{address}:{port}/api/participants", json={},
                               headers=bearer(study.experimenter_token)).json()["token"]
            with connect_socket(f"ws://{address}:{port}/ws", additional_headers=bearer(token),
                                open_timeout=5) as socket_:
                socket_.recv(timeout=5), socket_.recv(timeout=5)
                started = time.monotonic()
                assert "nothing received" in json.loads(socket_.recv(timeout=3.0))["detail"]
                with pytest.raises(ConnectionClosed) as closed:
                    socket_.recv(timeout=3.0)
                assert closed.value.rcvd is not None and closed.value.rcvd.code == IDLE
                assert time.monotonic() - started < 3.0
    finally:
        study.close()


@pytest.fixture
def served(tmp_path):
    """(address, study) of the application on uvicorn in a thread, requests cut after 0.4 s."""
    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions(request_seconds=0.4)).open()
    try:
        with serving(study) as address:
            yield address, study
    finally:
        study.close()


def host(address) -> bytes:
    """The Host header line of a request to the served `address` (one the server answers)."""
    return f"Host: {address[0]}:{address[1]}".encode()


def closed_within(address, data: bytes, seconds: float) -> tuple[bool, bytes]:
    """(whether the server closed the connection within `seconds`, what it sent)."""
    with socket.create_connection(address, timeout=seconds) as connection:
        if data:
            connection.sendall(data)
        received = b""
        try:
            while chunk := connection.recv(4096):
                received += chunk
            return True, received
        except TimeoutError:
            return False, received


def test_idle_and_slow_connections_are_closed(served):
    address, _ = served
    assert closed_within(address, b"", 2.0)[0]                                         # idle
    assert closed_within(address, b"GET /api/me HTTP/1.1\r\n%s\r\n" % host(address), 2.0)[0]   # slow headers
    body = (b"POST /api/claim HTTP/1.1\r\n%s\r\nContent-Type: application/json\r\n"
            b"Content-Length: 60\r\n\r\n{" % host(address))
    assert closed_within(address, body, 2.0)[0]                                        # slow body
    whole = b"GET /static/live.css HTTP/1.1\r\n%s\r\nConnection: close\r\n\r\n" % host(address)
    closed, received = closed_within(address, whole, 2.0)
    assert closed and received.startswith(b"HTTP/1.1 200")                              # a whole request


def served_request(connection: socket.socket, path: str = "/api/me") -> bytes:
    """One keep-alive request on an open connection: its whole response (by its Content-Length)."""
    connection.sendall(b"GET %s HTTP/1.1\r\n%s\r\n\r\n" % (path.encode(), host(connection.getpeername())))
    received = b""
    while b"\r\n\r\n" not in received:
        received += connection.recv(4096)
    head, body = received.split(b"\r\n\r\n", 1)
    length = int(next(line.split(b":")[1] for line in head.split(b"\r\n")
                      if line.lower().startswith(b"content-length:")))
    while len(body) < length:
        body += connection.recv(4096)
    return head + b"\r\n\r\n" + body


@pytest.mark.parametrize("options, held_count", [
    (ServerOptions(request_seconds=5.0, max_connections=4), 4),
    # one address's cap, the cap in all far from reached
    (ServerOptions(request_seconds=5.0, max_connections=40,
                   connections_per_address=CONNECTIONS_PER_PARTICIPANT), CONNECTIONS_PER_PARTICIPANT)],
    ids=["in-all", "per-address"])
def test_connections_beyond_the_cap_are_refused_at_once(tmp_path, options, held_count):
    """With the study's connections all open (or one address's), one more is answered 503 and
    closed as it is accepted (it holds no descriptor until a deadline); those open are still
    served, and once one closes a new connection is served again."""
    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", options).open()
    try:
        with serving(study) as address:
            held = [socket.create_connection(address, timeout=5) for _ in range(held_count)]
            try:
                assert all(served_request(c).startswith(b"HTTP/1.1 403") for c in held)   # all accepted
                started = time.monotonic()
                closed, received = closed_within(address, b"", 3.0)
                assert closed and received.startswith(b"HTTP/1.1 503") and b"too many" in received
                assert time.monotonic() - started < 2.0
                assert served_request(held[1]).startswith(b"HTTP/1.1 403")
                held.pop(0).close()
                whole = b"GET /static/live.css HTTP/1.1\r\n%s\r\nConnection: close\r\n\r\n" % host(address)
                deadline = time.monotonic() + 3.0
                while not (received := closed_within(address, whole, 2.0)[1]).startswith(b"HTTP/1.1 200"):
                    assert time.monotonic() < deadline, received[:80]   # (the server sees the close soon)
                    time.sleep(0.05)
            finally:
                for connection in held:
                    connection.close()
    finally:
        study.close()


def test_the_connection_cap_is_sized_for_the_study_within_the_open_file_limit():
    files = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    assert connection_cap(12) == 12 * CONNECTIONS_PER_PARTICIPANT + CONNECTIONS_SPARE <= files // 2
    assert connection_cap(10**6) <= files // 2   # half the descriptors stay for episodes and files


def test_accept_failures_for_want_of_descriptors_are_said_once():
    """asyncio reports every accept() that fails for want of file descriptors (with a traceback,
    and tries again a second later): the server's loop says it once, in one line."""
    records: list[logging.LogRecord] = []
    handler = logging.Handler()
    handler.emit = records.append
    logger = logging.getLogger("uvicorn.error")
    logger.addHandler(handler)
    loop = asyncio.new_event_loop()
    try:
        quiet_accept_errors(loop)
        for _ in range(3):
            loop.call_exception_handler({"message": "socket.accept() out of system resource",
                                         "exception": OSError(errno.EMFILE, "Too many open files")})
    finally:
        loop.close()
        logger.removeHandler(handler)
    assert len(records) == 1 and records[0].exc_info is None
    assert "file descriptors" in records[0].getMessage() and "\n" not in records[0].getMessage()


def test_a_chunked_body_is_refused_before_it_is_read(served):
    """A body framed by Transfer-Encoding has no length to check before it is read: it is refused
    at its headers, whatever Content-Length says beside it, and the connection closed."""
    address, _ = served
    for length in (b"Content-Length: 2\r\n", b""):
        head = (b"POST /api/claim HTTP/1.1\r\n%s\r\nContent-Type: application/json\r\n" % host(address)
                + length + b"Transfer-Encoding: chunked\r\n\r\n")
        chunk = b"100000\r\n" + b"a" * 0x10000   # the first 64 KiB of a 1 MiB chunk
        closed, received = closed_within(address, head + chunk, 2.0)
        assert closed and received.startswith(b"HTTP/1.1 411"), (length, received[:80])
        assert b"Transfer-Encoding" in received


def test_a_public_host_warns_and_prints_usable_addresses(live_study, capsys):
    from trustroute.harness.commands.live import announce

    announce(live_study, "0.0.0.0", 8765, ("https://study.example.org",))
    out, err = capsys.readouterr()
    host_warning, cookie_warning = err.splitlines()   # (without --secure-cookies: the test below)
    assert host_warning.startswith("warning: --host 0.0.0.0") and "--secure-cookies" in cookie_warning
    consoles = [line for line in out.splitlines() if line.startswith("console: ")]
    assert consoles and not any("0.0.0.0" in line for line in consoles)
    assert any("http://127.0.0.1:8765/login?token=" in line for line in consoles)
    assert any(line.startswith("console: https://study.example.org/login?token=") for line in consoles)
    announce(live_study, "127.0.0.1", 8765, ())
    assert capsys.readouterr().err == ""


def test_an_https_public_origin_without_secure_cookies_warns(tmp_path, capsys):
    """Behind an HTTPS proxy the cookies must be Secure, or a browser sends them over plain HTTP
    too (a participant typing http://...): served so without --secure-cookies, the server says so."""
    from trustroute.harness.commands.live import announce

    for secure in (False, True):
        options = ServerOptions(secure_cookies=secure, public_origins=("https://study.example.org",))
        with LiveStudy(tiny_config(tmp_path), tmp_path / f"study-{secure}", options) as study:
            announce(study, "127.0.0.1", 8765, options.public_origins)
            announce(study, "127.0.0.1", 8765, ("http://study.example.org",))
        err = capsys.readouterr().err
        assert err == ("" if secure else
                       "warning: https://study.example.org is HTTPS but the cookies are not marked Secure, "
                       "so a browser also sends them over plain HTTP; add --secure-cookies\n")


def test_the_server_sends_each_message_at_once_nagle_off(live_study):
    """A station's connection to the server as `trustroute live` binds it has Nagle's algorithm
    off: with it on, a mode event written behind a frame not yet acknowledged waits for the
    station's delayed acknowledgement (40 ms on Linux), the whole of the input latency."""
    from websockets.sync.client import connect

    with live_server_of(live_study) as (server, (host, port)):
        token = httpx.post(f"http://{host}:{port}/api/participants", json={},
                           headers=bearer(live_study.experimenter_token)).json()["token"]
        with connect(f"ws://{host}:{port}/ws", additional_headers=bearer(token)) as station:
            assert json.loads(station.recv(timeout=10))["type"] == "welcome"
            accepted = [connection.transport.get_extra_info("socket")
                        for connection in list(server.server_state.connections)]
            assert accepted
            assert all(sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) for sock in accepted)


def test_a_port_in_use_is_one_line_and_exit_2_and_leaves_nothing(tmp_path, capsys):
    holder = bind("127.0.0.1", 0)
    try:
        port = str(holder.getsockname()[1])
        code, out, err = run_cli(capsys, "live", write_config(tmp_path), "--out", str(tmp_path / "study"),
                                 "--port", port)
    finally:
        holder.close()
    assert code == 2 and out == "" and err.count("\n") == 1 and port in err and "--port" in err
    assert not (tmp_path / "study").exists()


def test_a_new_link_revokes_the_old_token_and_is_logged(client, live_study):
    token = new_participant(client, live_study)
    assert client.post("/api/participants/0/link", headers=bearer(token)).status_code == 403
    with client.websocket_connect("/ws", headers=bearer(token)) as station:
        station.receive_json(), station.receive_json()
        issued = client.post("/api/participants/0/link", headers=bearer(live_study.experimenter_token))
        assert issued.status_code == 200 and issued.json()["link"] == f"/p/{issued.json()['token']}"
        assert station.receive_json()["type"] == "revoked"
        with pytest.raises(WebSocketDisconnect) as closed:
            station.receive_json()
        assert closed.value.code == POLICY_VIOLATION
    assert client.get("/api/me", headers=bearer(token)).status_code == 403
    assert client.get("/api/me", headers=bearer(issued.json()["token"])).json()["participant"] == 0
    lines = (live_study.study_dir / "live" / "tokens.jsonl").read_text().splitlines()
    log = [(entry["participant"], entry["event"]) for entry in map(json.loads, lines)]
    assert log == [(0, "new link issued by the experimenter")]
    unknown = client.post("/api/participants/5/link", headers=bearer(live_study.experimenter_token))
    assert unknown.status_code == 404


def test_a_claimed_link_closes_the_sockets_opened_with_it(client, live_study):
    """Opening a link in a browser replaces its token: a socket opened with the link's token (by
    whoever had the link first) is told `revoked` and closed, and what it sends after the claim
    changes nothing."""
    token = new_participant(client, live_study)
    with client.websocket_connect("/ws", headers=bearer(token)) as early:
        early.receive_json(), early.receive_json()
        assert client.post("/api/claim", json={"token": token}).status_code == 200
        early.send_json({"type": "consent", "agree": True, "client": "scripted", "lockstep": True})
        assert early.receive_json()["type"] == "revoked"
        with pytest.raises(WebSocketDisconnect) as closed:
            early.receive_json()
        assert closed.value.code == POLICY_VIOLATION
    assert live_study.sessions[0].phase == "consent" and live_study.sessions[0].push is None
    assert not json.loads(live_study.registry_path().read_text())["participants"]["0"]["consented"]


def test_without_configured_origins_a_request_must_come_from_the_address_it_was_sent_to(live_study):
    with TestClient(live_app(live_study)) as client:   # no origins: the Host decides
        headers = bearer(live_study.experimenter_token)
        foreign = client.post("/api/participants", json={}, headers={**headers, "Origin": "http://evil.example"})
        assert foreign.status_code == 403
        same = client.post("/api/participants", json={}, headers={**headers, "Origin": "http://testserver"})
        assert same.status_code == 200


def test_a_scripted_participant_on_a_streaming_trial_keeps_its_socket_open(tmp_path, monkeypatch):
    """The server's idle rule counts what a socket sends, not what it receives: a participant who
    only watches a trial stream its frames is closed unless it pings. The scripted participant
    pings by what it has sent (a trial at pace 10 streams its frames for seconds, longer than the
    idle time here)."""
    monkeypatch.setattr(scripted, "PING_SECONDS", 0.3)
    config = tiny_config(tmp_path, participants=1)
    options = ServerOptions(pace=10.0, idle_seconds=1.5, warm_up=False)
    study = LiveStudy(config, tmp_path / "study", options).open()
    try:
        with serving(study) as (host, port):
            address = f"{host}:{port}"
            headers = {"Authorization": f"Bearer {study.experimenter_token}"}
            token = httpx.post(f"http://{address}/api/participants", json={}, headers=headers).json()["token"]
            player = scripted.ScriptedParticipant(config, 0)
            scripted.run_scripted(f"ws://{address}/ws", token, player, 60, stop_after=1)
            assert len(player.episodes) == 1
    finally:
        study.close()


class EpisodeEnd:
    """The session's end of a running episode's pipe: the controls the session tells it."""

    def __init__(self) -> None:
        self.controls: list[dict] = []

    def send(self, control: dict) -> None:
        self.controls.append(control)


def running(client, study):
    """The session of a new participant of `study` with an episode running (its pipe an
    EpisodeEnd) and its station's messages collected: (session, the messages pushed)."""
    new_participant(client, study)
    session = study.sessions[max(study.sessions)]
    pushed: list[dict] = []
    session.attach(pushed.append)
    session.phase, session.task = "driving", session.tasks[0]
    session.connection = EpisodeEnd()
    return session, pushed


def test_the_experimenters_pause_and_resume_reach_the_station(client, live_study):
    session, pushed = running(client, live_study)
    session.control("pause")
    assert [(m["type"], m["phase"], m["paused_by"]) for m in pushed] == [("state", "paused", "experimenter")]
    session.control("resume")
    assert (pushed[-1]["phase"], pushed[-1]["paused_by"]) == ("driving", None)
    assert [c["type"] for c in session.connection.controls] == ["pause", "resume"]


def test_an_accepted_trust_report_is_acknowledged_and_a_refused_one_is_not(client, live_study):
    session, _ = running(client, live_study)
    prompt = {"episode_id": session.task.episode_id, "road": 2}
    session.prompted.add(2)
    assert session.handle(parse_client_message('{"type": "trust", "value": 5}')) == [
        {"type": "reported", "value": 5, "prompt": None}]
    answer = json.dumps({"type": "trust", "value": 3, "prompt": prompt})
    assert session.handle(parse_client_message(answer)) == [
        {"type": "reported", "value": 3, "prompt": prompt}]
    session.control("pause")
    with pytest.raises(MessageError):   # refused: no acknowledgement, nothing told to the episode
        session.handle(parse_client_message('{"type": "trust", "value": 4}'))
    assert [c.get("value") for c in session.connection.controls if c["type"] == "trust"] == [5, 3]


def test_a_hand_back_crossing_the_episodes_own_is_done_and_other_repeats_are_refused(client, live_study):
    """A hand-back asking for the mode the episode switched to on its own since the participant last
    asked (the commit point's hand-back) is acknowledged with the state and told to nobody; one on
    an autopilot the participant never left, one before their takeover is applied, and a second
    one stay out of order."""
    session, pushed = running(client, live_study)
    takeover, hand_back = (parse_client_message(json.dumps({"type": kind}))
                           for kind in ("takeover", "hand_back"))

    def refused(message) -> bool:
        with pytest.raises(MessageError) as info:
            session.handle(message)
        return info.value.reply["code"] == "out_of_order"

    assert refused(hand_back)   # never taken over
    assert session.handle(takeover) == []
    assert refused(hand_back)   # the takeover is not applied yet
    session.on_episode_message({"type": "mode", "mode": "manual", "t": 10.0})
    assert refused(takeover)
    session.on_episode_message({"type": "mode", "mode": "auto", "t": 20.0})   # the commit point's
    (reply,) = session.handle(hand_back)
    assert (reply["type"], reply["phase"], reply["mode"]) == ("state", "driving", "auto")
    assert refused(hand_back)   # asked twice
    # the participant's own hand-back leaves nothing to cross; one the episode refused (by wheel,
    # off the lane) still does, once the episode hands back itself
    assert session.handle(takeover) == []
    session.on_episode_message({"type": "mode", "mode": "manual", "t": 30.0})
    assert session.handle(hand_back) == []
    session.on_episode_message({"type": "mode", "mode": "auto", "t": 31.0})
    assert refused(hand_back)
    assert session.handle(takeover) == []
    session.on_episode_message({"type": "mode", "mode": "manual", "t": 40.0})
    assert session.handle(hand_back) == []
    session.on_episode_message({"type": "warning", "kind": "back_to_lane", "t": 40.5})
    session.on_episode_message({"type": "mode", "mode": "auto", "t": 45.0})
    assert [m["type"] for m in session.handle(hand_back)] == ["state"]
    told = [control["type"] for control in session.connection.controls]
    assert told == ["takeover", "takeover", "hand_back", "takeover", "hand_back"]


def test_a_participant_who_does_not_agree_leaves_only_that_fact(client, live_study):
    """`{"type": "consent", "agree": false}` ends the session: the socket is closed with reason
    "declined", the registry keeps only that and its time (no label, no token: their cookie opens
    nothing), no other file is written, a withdrawal has nothing to do, and a new link from the
    console asks for the consent again."""
    experimenter = bearer(live_study.experimenter_token)
    token = client.post("/api/participants", json={"label": "Ada L."}, headers=experimenter).json()["token"]
    files = live_study.files()
    with client.websocket_connect("/ws", headers=bearer(token)) as station:
        station.receive_json(), station.receive_json()
        station.send_json({"type": "consent", "agree": False})
        with pytest.raises(WebSocketDisconnect) as closed:
            while True:
                station.receive_json()
        assert (closed.value.code, closed.value.reason) == (POLICY_VIOLATION, "declined")
    record = json.loads(live_study.registry_path().read_text())["participants"]["0"]
    assert set(record) == {"declined", "declined_utc"} and record["declined"] is True
    assert live_study.files() == files
    assert client.get("/api/me", headers=bearer(token)).status_code == 403
    shown = client.get("/api/participants/0", headers=experimenter).json()
    assert (shown["phase"], shown["label"]) == ("declined", "")
    withdrawn = client.post("/api/participants/0/withdraw", json={"confirm": True}, headers=experimenter)
    assert withdrawn.status_code == 409 and "did not agree" in withdrawn.text
    again = client.post("/api/participants/0/link", headers=experimenter).json()["token"]
    with client.websocket_connect("/ws", headers=bearer(again)) as station:
        assert station.receive_json()["type"] == "welcome"
        assert station.receive_json()["phase"] == "consent"
        station.send_json({"type": "consent", "agree": True})
        assert station.receive_json()["phase"] == "ready"
    assert json.loads(live_study.registry_path().read_text())["participants"]["0"]["consented"]


def test_a_declined_consent_holds_across_restarts_and_is_not_withdrawn(tmp_path, capsys):
    from trustroute.harness.live.protocol import Consent

    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions()).open()
    try:
        study.create_participant()
        assert study.sessions[0].handle(Consent(type="consent", agree=False))[0]["phase"] == "declined"
    finally:
        study.close()
    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions()).open()
    try:
        assert study.sessions[0].phase == "declined" and 0 not in study.credentials.participants
    finally:
        study.close()
    code, _, err = run_cli(capsys, "withdraw", str(tmp_path / "study"), "0")
    assert_one_line_error(code, err, "participant 0 did not agree to take part")


def test_a_decline_just_before_a_withdrawal_takes_its_locks_is_not_withdrawn(tmp_path):
    """The participant declines between the experimenter's withdrawal being asked for and its
    taking the session's lock: the withdrawal is refused as for anyone who declined, and the
    session stays "declined" in memory as in the registry."""
    from trustroute.harness.live.protocol import Consent

    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions()).open()
    try:
        study.create_participant()
        session = study.sessions[0]
        real = session.lock

        class DeclineFirst:
            """The session's lock, the participant's decline slipped in before its first taking."""

            fired = False

            def __enter__(self):
                if not DeclineFirst.fired:
                    DeclineFirst.fired = True
                    session.lock = real
                    session.handle(Consent(type="consent", agree=False))
                return real.__enter__()

            def __exit__(self, *exc):
                return real.__exit__(*exc)

        session.lock = DeclineFirst()
        with pytest.raises(ValueError, match="did not agree to take part"):
            study.withdraw(0, "asked to")
        assert DeclineFirst.fired and session.phase == "declined"
        assert set(json.loads(study.registry_path().read_text())["participants"]["0"]) == {
            "declined", "declined_utc"}
    finally:
        study.close()
