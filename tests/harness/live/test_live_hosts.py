"""A served study answers only requests addressed to it: a page of another site whose name is made
to resolve to this machine (DNS rebinding) sends that site's name as its Host and is refused,
on a page, an API call and the websocket alike."""

from __future__ import annotations

import base64
import os
import socket

import httpx
import pytest

from trustroute.harness.live.guard import ConnectionGate, host_allowed, own_origins
from trustroute.harness.live.server import LiveStudy, ServerOptions

from .conftest import experimenter, live_server_of, tiny_config

PUBLIC = "https://study.example.org"


@pytest.fixture
def served(tmp_path):
    """((host, port), study, a participant's token) of a study served on 127.0.0.1 that is also
    reached at PUBLIC (behind a proxy); its participant may open websockets as fast as a test does."""
    options = ServerOptions(public_origins=(PUBLIC,))
    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", options).open()
    try:
        with live_server_of(study) as (server, (host, port)):
            server.config.app.state.gate = ConnectionGate(max_sockets=100, burst=100, rate=100.0)
            created = httpx.post(f"http://{host}:{port}/api/participants", json={},
                                 headers=experimenter(study))
            assert created.status_code == 200, created.text
            yield (host, port), study, created.json()["token"]
    finally:
        study.close()


def handshake(address: tuple[str, int], host: str, token: str) -> bytes:
    """The status line the server answers a websocket handshake addressed to `host` with."""
    key = base64.b64encode(os.urandom(16)).decode()
    request = (f"GET /ws HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
               f"Authorization: Bearer {token}\r\n\r\n")
    with socket.create_connection(address, timeout=5) as connection:
        connection.sendall(request.encode())
        received = b""
        while b"\r\n" not in received:
            chunk = connection.recv(4096)
            assert chunk, received
            received += chunk
    return received.split(b"\r\n", 1)[0]


def requests_with_host(address: tuple[str, int], study, token: str, host: str) -> list[int]:
    """The statuses of a page, an API call and the websocket's handshake addressed to `host`."""
    base = f"http://{address[0]}:{address[1]}"
    headers = {"Host": host}
    page = httpx.get(f"{base}/static/console.js", headers=headers)
    api = httpx.get(f"{base}/api/participants", headers={**headers, **experimenter(study)})
    status_line = handshake(address, host, token)
    return [page.status_code, api.status_code, int(status_line.split()[1])]


def test_a_request_addressed_to_another_host_is_refused(served):
    address, study, token = served
    port = address[1]
    for host in ("evil.example", f"evil.example:{port}", "127.0.0.1", f"127.0.0.1:{port + 1}",
                 f"localhost.evil.example:{port}", f"user@127.0.0.1:{port}", "study.example.org:80"):
        assert requests_with_host(address, study, token, host) == [421, 421, 421], host
    refusal = httpx.get(f"http://{address[0]}:{port}/static/console.js", headers={"Host": "evil.example"})
    detail = refusal.json()["detail"]
    assert detail["code"] == "forbidden" and "'evil.example'" in detail["detail"]
    assert "\n" not in detail["detail"]
    assert "--public-origin" in detail["detail"] and refusal.headers["x-frame-options"] == "DENY"
    assert len(study.sessions) == 1   # nothing was done


def test_a_request_without_a_host_is_refused(served):
    address, _, _ = served
    with socket.create_connection(address, timeout=5) as connection:
        connection.sendall(b"GET /static/live.css HTTP/1.0\r\n\r\n")   # (HTTP/1.0 needs no Host)
        received = b""
        while chunk := connection.recv(4096):
            received += chunk
    assert received.startswith(b"HTTP/1.1 421")


def test_the_addresses_the_server_is_reached_at_are_served(served):
    address, study, token = served
    port = address[1]
    for host in (f"127.0.0.1:{port}", f"localhost:{port}", f"LocalHost:{port}", f"[::1]:{port}",
                 "study.example.org", "study.example.org:443"):
        assert requests_with_host(address, study, token, host) == [200, 200, 101], host


def test_the_allowed_hosts_follow_the_bind_and_its_port():
    """Without a port a Host names port 80 (of http); a non-loopback bind is reached at its own
    address, and not at the loopback names."""
    default_port, other_port = own_origins("127.0.0.1", 80), own_origins("127.0.0.1", 8765)
    for host in ("127.0.0.1", "localhost", "[::1]", "localhost:80"):
        assert host_allowed({"host": host}, default_port), host
        assert not host_allowed({"host": host}, other_port), host
    bound = own_origins("192.0.2.7", 8765)
    assert host_allowed({"host": "192.0.2.7:8765"}, bound)
    assert not host_allowed({"host": "localhost:8765"}, bound)
    assert not host_allowed({}, bound)
    assert host_allowed({"host": "anything.example"}, None)   # an application embedded without `serve`
