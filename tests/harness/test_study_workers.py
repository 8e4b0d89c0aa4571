"""The study's process pool (harness/study/workers.py): workers that exit while they start, start
methods other than fork, and Ctrl-C while workers start. Workers killed mid-task and workers dying
with their parent are in test_study_faults.py, with the studies they fail."""

from __future__ import annotations

import os
import signal

import pytest


def test_workers_exiting_while_they_start_stop_the_pool(monkeypatch):
    from trustroute.harness.study import workers

    monkeypatch.setattr(workers, "die_with_parent", lambda _pid: os._exit(3))   # forked: the workers see it
    said = (r"exited with code 3, 2 in a row; each printed its error above\)"
            r".*__main__.*one worker \(--workers 1\)")
    with pytest.raises(workers.WorkersCannotStart, match=said):
        list(workers.process_pool(abs, [-1, -2, -3], 2, lambda _task, reason: reason))


def test_workers_killed_while_they_start_are_said_killed_not_to_have_printed_an_error(monkeypatch):
    """A worker killed by a signal (the out-of-memory killer's SIGKILL) prints nothing: the refusal
    names the signal and where to learn why, and never says each printed its error."""
    from trustroute.harness.study import workers

    monkeypatch.setattr(workers, "die_with_parent", lambda _pid: os.kill(os.getpid(), signal.SIGKILL))
    with pytest.raises(workers.WorkersCannotStart) as refused:
        list(workers.process_pool(abs, [-1, -2, -3], 2, lambda _task, reason: reason))
    said = str(refused.value)
    assert "(worker process killed by SIGKILL, 2 in a row; a process killed by a signal prints no " in said
    assert "dmesg" in said and "out-of-memory" in said and "printed its error" not in said
    assert refused.value.fix == workers.KILLED_FIX


def test_a_row_of_a_worker_exiting_then_one_killed_says_each_how_it_ended(monkeypatch, tmp_path):
    """One worker exits with an error (printed), the next is killed (nothing printed): the refusal
    says both, and which of them printed an error."""
    from trustroute.harness.study import workers

    once = tmp_path / "exited once"

    def exits_then_killed(_pid: int) -> None:
        if not once.exists():
            once.touch()
            os._exit(3)
        os.kill(os.getpid(), signal.SIGKILL)

    monkeypatch.setattr(workers, "die_with_parent", exits_then_killed)
    with pytest.raises(workers.WorkersCannotStart) as refused:
        list(workers.process_pool(abs, [-1, -2, -3], 1, lambda _task, reason: reason))
    said = str(refused.value)
    assert ("(worker process exited with code 3, then killed by SIGKILL, 2 in a row; each that exited "
            "printed its error above; a process killed by a signal prints no error") in said
    assert "__main__" in refused.value.fix and workers.KILLED_FIX in refused.value.fix


def test_one_worker_exiting_while_it_starts_fails_only_its_task(monkeypatch, tmp_path):
    from trustroute.harness.study import workers

    once = tmp_path / "exited once"

    def first_exits(_pid: int) -> None:
        if not once.exists():
            once.touch()
            os._exit(3)

    monkeypatch.setattr(workers, "die_with_parent", first_exits)
    results = list(workers.process_pool(abs, [-1, -2], 1, lambda task, reason: (task, reason)))
    assert results == [(-1, "worker process exited with code 3"), 2]


@pytest.mark.parametrize("method", ["spawn", "forkserver"])
def test_workers_that_are_not_forked_run_their_tasks(monkeypatch, method):
    """A spawned worker's parent is the study's process; a forkserver's is the fork server. Both
    workers are started before either is handed the function, so they import at the same time."""
    import multiprocessing
    import multiprocessing.connection

    from trustroute.harness.study import workers

    context = multiprocessing.get_context(method)
    monkeypatch.setattr(workers.multiprocessing, "get_context", lambda: context)
    send, started_at_handing = multiprocessing.connection.Connection.send, []

    def counted(connection, message) -> None:
        if callable(message):   # the task function, handed to a worker
            started_at_handing.append(len(multiprocessing.active_children()))
        send(connection, message)

    monkeypatch.setattr(multiprocessing.connection.Connection, "send", counted)
    before = len(multiprocessing.active_children())
    results = list(workers.process_pool(abs, [-1, -2, -3], 2, lambda task, reason: (task, reason)))
    assert sorted(results) == [1, 2, 3]
    assert [n - before for n in started_at_handing] == [2, 2], started_at_handing


def test_ctrl_c_while_workers_start_stops_those_started(monkeypatch):
    from trustroute.harness.study import workers

    started: list = []

    class InterruptedSecond(workers._Worker):
        def __init__(self, context, function) -> None:
            if started:
                raise KeyboardInterrupt
            super().__init__(context, function)
            started.append(self)

    monkeypatch.setattr(workers, "_Worker", InterruptedSecond)
    with pytest.raises(KeyboardInterrupt):
        list(workers.process_pool(abs, [-1, -2], 2, lambda task, reason: reason))
    assert len(started) == 1 and started[0].process.exitcode is not None


def test_ctrl_c_while_a_spawned_worker_is_handed_its_function_stops_it(monkeypatch):
    import multiprocessing
    import multiprocessing.connection

    from trustroute.harness.study import workers

    send = multiprocessing.connection.Connection.send

    def interrupted(connection, message) -> None:
        if callable(message):   # the task function, handed to a spawned worker
            raise KeyboardInterrupt
        send(connection, message)

    monkeypatch.setattr(multiprocessing.connection.Connection, "send", interrupted)
    before = set(multiprocessing.active_children())
    worker = workers._Worker(multiprocessing.get_context("spawn"), abs)
    with pytest.raises(KeyboardInterrupt):
        worker.hand()
    assert set(multiprocessing.active_children()) <= before


@pytest.mark.parametrize("method", ["spawn", "forkserver"])
def test_a_worker_stopped_before_it_is_handed_its_function_ends_quietly(method, capfd):
    """A pool interrupted after starting its workers and before handing them the function stops
    them: each returns at the end of its pipe (exit code 0), and none reads the stop word as its
    function and dies writing Ready into the closed pipe (a BrokenPipeError traceback, exit 1)."""
    import multiprocessing

    from trustroute.harness.study import workers

    worker = workers._Worker(multiprocessing.get_context(method), abs)
    worker.stop()
    worker.process.join(60)
    assert worker.process.exitcode == 0
    assert "Traceback" not in capfd.readouterr().err


def test_a_worker_that_became_ready_breaks_the_row_of_workers_exiting_while_they_start(monkeypatch):
    """Two workers exiting while they start stop the pool only in a row: one that became ready
    between them (it runs its tasks) shows the workers can start, and the next one's exit fails
    only its task. Workers stand in on pipes of this process, so the order is the test's: the
    first exits, the second becomes ready, then the third (the first's replacement) exits."""
    import multiprocessing
    import threading

    from trustroute.harness.study import workers

    class Exited:
        exitcode = 3

        def join(self, _timeout: float | None = None) -> None:
            pass

        def is_alive(self) -> bool:
            return False

    made: list = []

    class StandIn:
        def __init__(self, _context, _function) -> None:
            self.connection, self.other = multiprocessing.Pipe()
            self.process, self.task, self.ready = Exited(), None, False
            made.append(self)
            if len(made) == 1:
                self.other.close()   # exits before it is ready

        def hand(self) -> None:
            pass

        def stop(self) -> None:
            self.connection.close()

    def second_ready_then_third_exits() -> None:
        made[1].other.send(workers.Ready())
        while not made[1].ready:
            threading.Event().wait(0.01)
        made[2].other.close()

    monkeypatch.setattr(workers, "_Worker", StandIn)
    pool = workers.process_pool(abs, [-1, -2, -3, -4], 2, lambda task, reason: (task, reason))
    assert next(pool) == (-1, "worker process exited with code 3")
    helper = threading.Thread(target=second_ready_then_third_exits, daemon=True)
    helper.start()
    assert next(pool) == (-3, "worker process exited with code 3")
    pool.close()
    helper.join(5)


def test_workers_whose_pipe_closed_while_they_still_run_are_said_so():
    """A worker whose pipe closed but which had not exited when the pool looked (exit code None)
    neither exited nor printed an error: the refusal says what was seen."""
    from trustroute.harness.study import workers

    said = str(workers.WorkersCannotStart([None, None]))
    assert (f"(worker process closed its pipe and had not exited {workers.SHUTDOWN_SECONDS:g} s later, "
            "2 in a row)") in said, said
    assert "printed" not in said and "did not exit" not in said

