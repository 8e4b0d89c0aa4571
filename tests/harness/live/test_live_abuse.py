"""What a client can do to a served study without a token, or beyond its limits, against the real
server: refusals that write nothing to its log, one address that cannot hold every connection,
frames cut at the transport, and no token in the server's output during a session."""

from __future__ import annotations

import base64
import contextlib
import os
import re
import socket

import httpx
import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from tests.cli import run_cli
from trustroute.core.errors import InputError
from trustroute.harness.commands.live import ServeOptions
from trustroute.harness.live.guard import (
    CONNECTIONS_PER_ADDRESS,
    CONNECTIONS_PER_PARTICIPANT,
    address_cap,
    connection_cap,
)
from trustroute.harness.live.protocol import MAX_MESSAGE_BYTES
from trustroute.harness.live.server import LiveStudy, ServerOptions

from .conftest import experimenter, live_server_of, serving, tiny_config
from .test_live_cli import write_config
from .test_live_sessions import closed_within, host, served_request

pytestmark = pytest.mark.wallclock

LOGGED_FAILURES = ("Traceback", "Exception in ASGI application", "without completing handshake", "ERROR")
MESSAGE_CAP_AT_THE_TRANSPORT = 4 * MAX_MESSAGE_BYTES   # (app.live_server's ws_max_size)
MESSAGE_TOO_BIG = 1009   # the websocket close code of a frame beyond the transport's cap


@pytest.fixture
def study(tmp_path):
    opened = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions(request_seconds=5.0)).open()
    yield opened
    opened.close()


def answer(address, request: bytes) -> bytes:
    """What the server sends for `request` on a connection of its own, until it closes it."""
    closed, received = closed_within(address, request, 5.0)
    assert closed, received[:80]
    return received


def handshake(address, host_line: bytes, extra: bytes = b"") -> bytes:
    key = base64.b64encode(os.urandom(16))
    return (b"GET /ws HTTP/1.1\r\n" + host_line + b"\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            b"Sec-WebSocket-Key: " + key + b"\r\nSec-WebSocket-Version: 13\r\n" + extra + b"\r\n")


def test_refusals_of_clients_without_a_token_write_no_error_to_the_log(study, capfd):
    """A chunked POST whose framing breaks after its headers (uvicorn answers 400 and closes; the
    guard's own refusal must not follow on the closing connection) and a websocket handshake
    addressed to a foreign Host (refused 421) or carrying no token: each is refused, and the
    server's output holds no traceback or error line for any of them."""
    with live_server_of(study) as (_, address):
        broken = (b"POST /api/claim HTTP/1.1\r\n%s\r\nTransfer-Encoding: chunked\r\n\r\n"
                  b"5\r\n{}\r\n\r\n0\r\n\r\n" % host(address))
        for _ in range(3):
            assert answer(address, broken).startswith(b"HTTP/1.1 400")
            assert answer(address, handshake(address, b"Host: evil.example")).startswith(b"HTTP/1.1 421")
            assert answer(address, handshake(address, host(address))).startswith(b"HTTP/1.1 403")
    out, err = capfd.readouterr()   # (the server has stopped: all it had to say is said)
    for failure in LOGGED_FAILURES:
        assert failure not in out + err, (out + err)[:2000]


def test_the_cap_per_address_leaves_room_for_others_and_spares_loopback():
    """By default an address of another machine holds at most CONNECTIONS_PER_ADDRESS, fewer
    than the smallest study's cap in all; the machine's own (a proxy in front: every client) is
    capped only in all, unless a number is given."""
    assert CONNECTIONS_PER_ADDRESS < connection_cap(1)
    for other in ("192.0.2.7", "2001:db8::7", "::ffff:192.0.2.7"):
        assert address_cap(other, None) == CONNECTIONS_PER_ADDRESS, other
    for own in ("127.0.0.1", "127.0.0.2", "::1", "::ffff:127.0.0.1"):
        assert address_cap(own, None) is None, own
        assert address_cap(own, 3) == 3


def test_an_address_counts_its_websockets_toward_its_cap(tmp_path):
    """Websockets held from one address count toward its cap as its HTTP connections do: with two
    stations' sockets and the rest of the cap in HTTP connections open, one more connection from
    the address is answered 503 at once, the cap in all far from reached."""
    options = ServerOptions(request_seconds=5.0, max_connections=40,
                            connections_per_address=CONNECTIONS_PER_PARTICIPANT)
    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", options).open()
    try:
        tokens = [study.create_participant()[1] for _ in range(2)]
        with serving(study) as address, contextlib.ExitStack() as held:
            for token in tokens:
                held.enter_context(connect(f"ws://{address[0]}:{address[1]}/ws", open_timeout=5,
                                           additional_headers={"Authorization": f"Bearer {token}"}))
            for _ in range(CONNECTIONS_PER_PARTICIPANT - len(tokens)):
                connection = held.enter_context(socket.create_connection(address, timeout=5))
                assert served_request(connection).startswith(b"HTTP/1.1 403")   # accepted
            closed, received = closed_within(address, b"", 3.0)
            assert closed and received.startswith(b"HTTP/1.1 503") and b"too many" in received
    finally:
        study.close()


def test_one_address_s_cap_is_at_least_a_browser_s_at_every_door(tmp_path, capsys):
    """`--connections-per-address` and `ServerOptions.connections_per_address` take a count of at
    least one browser's connections (the cap holds this machine's address too, so fewer would
    starve the console's browser): one line, exit 2, as its range says; a count given reaches the
    server's options."""
    for value in ("0", "-3", "1.5", str(CONNECTIONS_PER_PARTICIPANT - 1)):
        code, out, err = run_cli(capsys, "live", write_config(tmp_path), "--out", str(tmp_path / "study"),
                                 "--connections-per-address", value)
        assert code == 2 and err.count("\n") == 1 and "--connections-per-address" in err and out == "", err
    with pytest.raises(InputError, match="connections-per-address"):
        ServerOptions(connections_per_address=CONNECTIONS_PER_PARTICIPANT - 1)
    assert ServeOptions(connections_per_address=256).server_options().connections_per_address == 256
    assert not (tmp_path / "study").exists()


def participant_token(base: str, study) -> str:
    created = httpx.post(f"{base}/api/participants", json={}, headers=experimenter(study))
    assert created.status_code == 200, created.text
    return created.json()["token"]


def test_a_frame_beyond_the_transports_cap_closes_the_socket(study):
    """A frame a little above MAX_MESSAGE_BYTES is the application's to refuse (an error reply);
    one beyond the transport's cap is never read whole: the socket is closed 1009."""
    with serving(study) as (address, port):
        token = participant_token(f"http://{address}:{port}", study)
        with connect(f"ws://{address}:{port}/ws", additional_headers={"Authorization": f"Bearer {token}"},
                     open_timeout=5) as station:
            station.recv(timeout=5), station.recv(timeout=5)   # the welcome, the consent's state
            station.send('{"type": "ping", "pad": "%s"}' % ("x" * MESSAGE_CAP_AT_THE_TRANSPORT))
            with pytest.raises(ConnectionClosed) as closed:
                while True:
                    station.recv(timeout=5)
    assert closed.value.rcvd is not None and closed.value.rcvd.code == MESSAGE_TOO_BIG


def test_no_token_reaches_the_servers_output_during_a_session(study, capfd):
    """A participant's link opened and claimed, their station connected, the console logged in
    from its link: none of the tokens (link, cookies, experimenter's, login's) is printed."""
    with live_server_of(study) as (_, (address, port)):
        base = f"http://{address}:{port}"
        link_token = participant_token(base, study)
        login_token = study.new_login_link()
        with httpx.Client(base_url=base) as station, httpx.Client(base_url=base) as console:
            assert station.get(f"/p/{link_token}").status_code == 200
            assert station.post("/api/claim", json={"token": link_token}).status_code == 200
            cookie = station.cookies.get("trustroute_participant")
            with connect(f"ws://{address}:{port}/ws", open_timeout=5,
                         additional_headers={"Cookie": f"trustroute_participant={cookie}"}) as socket_:
                socket_.recv(timeout=5), socket_.recv(timeout=5)
                socket_.send('{"type": "consent", "agree": true}')
                assert '"ready"' in str(socket_.recv(timeout=5))
            assert console.get(f"/login?token={login_token}", follow_redirects=True).status_code == 200
            console_cookie = console.cookies.get("trustroute_experimenter")
            assert console.get("/api/participants").status_code == 200
    out, err = capfd.readouterr()
    tokens = [link_token, cookie, login_token, console_cookie, study.experimenter_token]
    assert all(tokens) and len(set(tokens)) == len(tokens)
    printed = out + err
    for token in tokens:
        assert token not in printed, printed[:2000]
    assert not re.search(r"token=\S{20}", printed), printed[:2000]
