"""benchmarks/result_digest.py gives no digest of an entry the wall clock cut: its result would
depend on the machine's load, and two digests of one commit would differ silently."""

from __future__ import annotations

import os

import pytest

from benchmarks import result_digest

ENTRY = "phi1_strict_robust_H10"


def test_an_entry_the_wall_clock_cut_gets_no_digest_but_one_line_and_exit_2(monkeypatch, capsys, tmp_path):
    calls = []

    def run(args: list[str], cache) -> dict:
        calls.append(args[0])
        return {"lower": 0.78, "upper": 0.83, "stopped_by": "time limit"}

    monkeypatch.setattr(result_digest, "_run", run)
    out = tmp_path / "digest.json"
    with pytest.raises(SystemExit) as stopped:
        result_digest.main([str(out), "--only", ENTRY])
    assert stopped.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert err.startswith(f"{ENTRY}: ") and "rerun on a quieter machine or raise its time limit" in err
    assert "600 s time limit" in err
    assert calls == ["synth"] and not out.exists()     # not evaluated, no digest written


def test_the_digests_commands_cache_in_a_root_of_their_own(monkeypatch, tmp_path):
    """Each command the digest runs is given a cache root in the digest's work folder (a policy
    cached by another tree would otherwise be read), and the caller's own root is left as it was."""
    import subprocess

    environments = []

    def run(command, **options):
        environments.append(options["env"])
        return subprocess.CompletedProcess(command, 0, stdout="{}", stderr="")

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "callers"))
    monkeypatch.setattr(result_digest.subprocess, "run", run)
    result_digest.digest(tmp_path, ["study_model"])
    assert [env["XDG_CACHE_HOME"] for env in environments] == [str(tmp_path / "cache")]
    assert environments[0]["PYTHONHASHSEED"] == "0"
    assert os.environ["XDG_CACHE_HOME"] == str(tmp_path / "callers")


@pytest.mark.parametrize("stopped_by", ["work limit", "convergence"])
def test_an_entry_its_work_limit_or_convergence_ended_is_digested(stopped_by):
    args = dict(result_digest.SYNTHESES)[ENTRY]
    result_digest.refuse_clock_cut(ENTRY, args, {"stopped_by": stopped_by})     # no exit


# read as every JSON input is (trustroute/core/validation.py, read_json): nesting too deep for
# json.loads to parse without a RecursionError is one line too
@pytest.mark.parametrize("text", [None, "{not json", "[1]", "[" * 100_000, '{"a": 1, "a": 2}'])
def test_comparing_a_file_that_is_no_digest_is_one_line_and_exit_2(tmp_path, capsys, text):
    good, bad = tmp_path / "good.json", tmp_path / "bad.json"
    good.write_text("{}\n")
    if text is not None:
        bad.write_text(text)
    with pytest.raises(SystemExit) as stopped:
        result_digest.main([str(bad), str(good)])
    assert stopped.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert str(bad) in err and "fix:" in err
