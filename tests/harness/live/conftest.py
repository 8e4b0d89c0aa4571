"""A tiny live study (one participant, one trial of φ1 on the trust-free route) for the live tests."""

from __future__ import annotations

import contextlib
import threading
import time

import pytest

from trustroute.harness.live.server import LiveStudy, ServerOptions
from trustroute.harness.study.config import load_study_config

TINY = """[study]
name = "tiny-live"
participants = {participants}
seed = 1
engine = "live"
specs = {specs}
conditions = ["free"]
"""


def tiny_config(tmp_path, participants: int = 2, specs: tuple[str, ...] = ("phi1",)):
    path = tmp_path / "live.toml"
    path.write_text(TINY.format(participants=participants, specs=list(specs)).replace("'", '"'))
    return load_study_config(path)


@pytest.fixture
def live_study(tmp_path):
    """An open live study at pace 1000 in tmp_path/study (closed after the test)."""
    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions(pace=1000.0)).open()
    yield study
    study.close()


@contextlib.contextmanager
def live_server_of(study):
    """The application of the open `study` on uvicorn in a thread, on a free port of 127.0.0.1
    bound as `trustroute live` binds it: yields (the uvicorn server, its (host, port))."""
    from trustroute.harness.live.app import live_server
    from trustroute.harness.live.guard import bind

    sock = bind("127.0.0.1", 0)
    server = live_server(study, sock)
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    try:
        while not server.started:
            time.sleep(0.01)
        yield server, sock.getsockname()[:2]
    finally:
        server.should_exit = True
        thread.join(5)
        sock.close()


@contextlib.contextmanager
def serving(study):
    """`live_server_of`'s (host, port)."""
    with live_server_of(study) as (_, address):
        yield address


def experimenter(study) -> dict:
    """The experimenter's Authorization header for `study`."""
    return {"Authorization": f"Bearer {study.experimenter_token}"}


@contextlib.contextmanager
def consenting_participant(client, study):
    """A new participant of `study` whose websocket on `client` (a TestClient of its app) has sent
    its consent: yields (the socket, the participant's Authorization header, for reconnecting)."""
    token = client.post("/api/participants", json={}, headers=experimenter(study)).json()["token"]
    participant = {"Authorization": f"Bearer {token}"}
    with client.websocket_connect("/ws", headers=participant) as station:
        station.send_json({"type": "consent", "agree": True})
        yield station, participant
