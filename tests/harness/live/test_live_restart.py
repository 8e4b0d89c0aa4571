"""A server killed (SIGKILL) in the middle of an episode loses no finished episode: its episode
process dies with it, and a restarted server continues the participant at the interrupted trial
without a duplicated row. A server stopped with SIGTERM closes the study as Ctrl-C does."""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from pathlib import Path
from typing import NamedTuple

import httpx
import pytest
from websockets.exceptions import ConnectionClosed

from benchmarks.bench_live import start_live_server
from trustroute.core.dataset import part_path, read_episodes, read_roads
from trustroute.harness.live.scripted import ScriptedParticipant, run_scripted
from trustroute.harness.live.server import LIVE_DIR, PARTICIPANTS_FILE
from trustroute.harness.study.plan import plan_episodes

from .conftest import tiny_config

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]


def start_server(config_path: str, study_dir: Path, pace: float) -> tuple[subprocess.Popen, str, str]:
    """(process, address, experimenter token) of `trustroute live` once it serves."""
    return start_live_server(config_path, study_dir, "--pace", str(pace), wait=60.0)


def children(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                found.append(int(entry.name))
    return found


def descendants(pid: int) -> list[int]:
    """Every process below `pid`: the episode processes are forked by the server's fork server."""
    found = children(pid)
    for child in list(found):
        found += descendants(child)
    return found


def alive(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def play_until_the_server_dies(url: str, token: str, participant: ScriptedParticipant) -> None:
    with pytest.raises((ConnectionClosed, OSError)):   # the connection breaks when the server is killed
        run_scripted(url, token, participant, 120)


def drive_into_the_second_trial(config, address: str, token: str, first: str) -> tuple[str, threading.Thread]:
    """A new participant's token and the thread that drives them (until the server dies), once they
    finished the episode `first` and drive the next."""
    headers = {"Authorization": f"Bearer {token}"}
    created = httpx.post(f"http://{address}/api/participants", json={}, headers=headers)
    participant = created.json()["token"]
    player = threading.Thread(target=play_until_the_server_dies, daemon=True,
                              args=(f"ws://{address}/ws", participant, ScriptedParticipant(config, 0)))
    player.start()
    deadline = time.monotonic() + 120
    with httpx.Client(headers=headers) as client:   # one TLS context for the polling, not one per poll
        while True:
            progress = client.get(f"http://{address}/api/participants/0").json()
            if progress["done"] == [first] and progress["phase"] == "driving":
                return participant, player
            assert time.monotonic() < deadline, progress
            time.sleep(0.05)


class Signalled(NamedTuple):
    """A study whose server got a signal mid-drive (`signalled_in_the_second_trial`)."""

    config: object
    study_dir: Path
    first: object        # the trial that was done (an EpisodeTask)
    second: object       # the trial that was driven when the signal came
    participant: str     # the participant's token
    printed: str         # what the server printed
    returncode: int


def signalled_in_the_second_trial(tmp_path: Path, sent: signal.Signals) -> Signalled:
    """A served study of one participant and two trials, sent `sent` while its participant drives
    the second: once its episode processes (which die with their server) and the participant's
    thread have ended, the first trial's part is kept and the second's was never written."""
    config = tiny_config(tmp_path, participants=1, specs=("phi1", "phi2"))
    study_dir = tmp_path / "study"
    first, second = sorted(plan_episodes(config), key=lambda t: t.position)
    server, address, token = start_server(config.source_path, study_dir, pace=10.0)
    try:
        participant, player = drive_into_the_second_trial(config, address, token, first.episode_id)
        workers = descendants(server.pid)
        assert len(workers) > len(children(server.pid)), "the episode runs in a process of its own"
        server.send_signal(sent)
        printed, _ = server.communicate(timeout=60)
    finally:
        if server.poll() is None:
            server.kill()
            server.wait()
    deadline = time.monotonic() + 10   # the fork server sees its server gone a moment later
    while any(alive(pid) for pid in workers):
        assert time.monotonic() < deadline, "an episode process outlived its server"
        time.sleep(0.05)
    player.join(30)
    assert part_path(study_dir, first.episode_id).exists()
    assert not part_path(study_dir, second.episode_id).exists()
    return Signalled(config, study_dir, first, second, participant, printed, server.returncode)


def test_sigkill_mid_episode_then_restart_continues_at_the_interrupted_trial(tmp_path):
    killed = signalled_in_the_second_trial(tmp_path, signal.SIGKILL)
    config, study_dir, first, second, participant = killed[:5]
    server, address, token = start_server(config.source_path, study_dir, pace=1000.0)
    try:
        progress = httpx.get(f"http://{address}/api/participants/0",
                             headers={"Authorization": f"Bearer {token}"}).json()
        assert progress["phase"] == "ready" and progress["warm_up"] == "done"   # consent and warm-up hold
        assert progress["done"] == [first.episode_id] and progress["next_episode"] == second.episode_id
        played = run_scripted(f"ws://{address}/ws", participant, ScriptedParticipant(config, 0), 120)
        assert [e["episode_id"] for e in played.episodes] == [second.episode_id]
    finally:
        os.kill(server.pid, signal.SIGTERM)
        server.wait(30)
    episodes, roads = read_episodes(study_dir), read_roads(study_dir)
    assert sorted(episodes["episode_id"]) == sorted([first.episode_id, second.episode_id])
    assert not roads.duplicated(["episode_id", "index"]).any()
    assert len(roads) == int(episodes["junctions"].sum()) + len(episodes)


def test_sigterm_mid_episode_closes_the_study_with_the_interrupted_line(tmp_path):
    """SIGTERM while a participant drives: the server shuts down as on Ctrl-C (exit 130, the one
    interrupted line, no traceback), its episode processes end, and what was written stays."""
    from trustroute.harness.cli import interrupted_line

    ended = signalled_in_the_second_trial(tmp_path, signal.SIGTERM)
    assert ended.returncode == 130 and "Traceback" not in ended.printed, ended.printed
    assert ended.printed.splitlines()[-1] == interrupted_line("live"), ended.printed
    assert (ended.study_dir / LIVE_DIR / PARTICIPANTS_FILE).exists()


def test_sigterm_while_the_study_opens_leaves_its_directory_free(tmp_path, monkeypatch):
    """SIGTERM (or Ctrl-C) while the fork server starts, the slowest part of opening a study,
    unwinds what the opening took: the study directory's lock is let go, so the same study opens
    again in this process (an API caller's retry) as in a new one."""
    from trustroute.core.interrupts import Terminated
    from trustroute.harness.live import server as live_server
    from trustroute.harness.live.server import LiveStudy, ServerOptions

    config = tiny_config(tmp_path)

    def terminated() -> None:
        raise Terminated()

    monkeypatch.setattr(live_server, "start_fork_server", terminated)
    interrupted = LiveStudy(config, tmp_path / "study", ServerOptions())   # held, as a caller may
    with pytest.raises(Terminated):
        interrupted.open()
    monkeypatch.undo()
    LiveStudy(config, tmp_path / "study", ServerOptions()).open().close()
