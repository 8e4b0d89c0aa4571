"""The README's "Python API" script runs as written (in a temporary directory and cache)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def api_script() -> str:
    text = README.read_text()
    section = text[text.index("## Python API"):]
    section = section[: section.index("\n## ", 1)]
    blocks = re.findall(r"```python\n(.*?)```", section, re.S)
    assert len(blocks) == 1, "the Python API section has exactly one script"
    return blocks[0]


def test_api_names_are_cheap_to_reach():
    code = ("import sys, trustroute\n"
            "names = ['load_town', 'load_driver_model', 'load_spec', 'synthesize', 'evaluate',"
            " 'run_episode', 'run_study', 'analyze']\n"
            "assert all(callable(getattr(trustroute, n)) and getattr(trustroute, n).__doc__ for n in names)\n"
            "heavy = [m for m in ('numpy', 'pandas', 'click', 'libsumo', 'gymnasium') if m in sys.modules]\n"
            "assert not heavy, heavy\n")
    subprocess.run([sys.executable, "-c", code], check=True)


# Runs the script as `python api_script.py` would, with the processes of `run_study` spawned, as they
# are on macOS, on Windows and (forkserver) under Python 3.14 on Linux: each worker imports the
# script again, which must not run the study again.
SPAWNED = ("import multiprocessing, runpy, sys\n"
           "multiprocessing.set_start_method('spawn')\n"
           "runpy.run_path(sys.argv[1], run_name='__main__')\n")


def script_environment(folder: Path, cache: Path) -> dict[str, str]:
    """A script's environment: its home in `folder`, its cache the run's temporary root (tests/
    conftest.py, `temporary_cache`), never the real ~/.cache. The nets and policies a script makes
    are those other tests make (the packaged town's net, its policies at a study's default
    horizon): read there, they are not built again in each script's process."""
    return {**os.environ, "HOME": str(folder / "home"), "XDG_CACHE_HOME": str(cache)}


@pytest.mark.slow
def test_readme_api_script_runs(tmp_path, temporary_cache):
    script = tmp_path / "api_script.py"
    script.write_text(api_script())
    env = script_environment(tmp_path, temporary_cache)
    done = subprocess.run([sys.executable, "-c", SPAWNED, str(script)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    bounds = re.fullmatch(r"(\S+) <= Pr_max\(12 junctions\) <= (\S+)", lines[0])
    assert bounds and 0 < float(bounds.group(1)) <= float(bounds.group(2)) <= 1
    assert re.fullmatch(r"P\(satisfied\): aware \S+, free \S+", lines[1])
    assert re.fullmatch(r"SUMO episode: (accepted|rejected|destination|cap) after \d+ junctions", lines[2])
    cells = [line.split() for line in lines[3:]]
    assert [(c[0], c[1]) for c in cells] == [("phi1", "aware"), ("phi1", "free")]
    assert all(c[2].endswith("/4") for c in cells)
    assert (tmp_path / "studies" / "api-demo" / "episodes.parquet").is_file()
    assert not (tmp_path / "studies" / "api-demo" / "report.md").exists()  # analyze wrote nothing


def test_the_settings_classes_import_from_where_the_readme_says():
    """Each "`Name` ... from `module`" the API section names imports, and is the class the API's
    calls take as `settings=`."""
    import importlib
    import inspect

    import trustroute

    section = README.read_text()
    section = section[section.index("## Python API"):section.index("```python")]
    section = " ".join(section.split())
    named = re.findall(r"((?:`\w+Settings`(?: and |, )?)+) from `([\w.]+)`", section)
    found = {name: module for names, module in named for name in re.findall(r"`(\w+)`", names)}
    assert set(found) == {"SynthesisSettings", "EvaluationSettings", "EpisodeSettings"}, found
    calls = {"SynthesisSettings": trustroute.synthesize, "EvaluationSettings": trustroute.evaluate,
             "EpisodeSettings": trustroute.run_episode}
    for name, module in found.items():
        cls = getattr(importlib.import_module(module), name)
        annotation = str(inspect.signature(calls[name]).parameters["settings"].annotation)
        assert annotation.startswith(name) and inspect.isclass(cls) and cls() is not None


UNGUARDED = """import trustroute
trustroute.run_study({"study": {"participants": 4, "seed": 1, "engine": "model", "specs": ["phi1"],
                                "conditions": ["aware", "free"]}}, out="studies/unguarded", workers=2)
"""


@pytest.mark.slow
def test_a_script_without_a_main_guard_stops_with_the_fix_on_spawned_workers(tmp_path, temporary_cache):
    """Each spawned worker runs the unguarded script again and exits while it starts; the study
    stops with one line saying why instead of spawning a worker per task (or blocking on one)."""
    script = tmp_path / "unguarded.py"
    script.write_text(UNGUARDED)
    env = script_environment(tmp_path, temporary_cache)
    done = subprocess.run([sys.executable, "-c", SPAWNED, str(script)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("trustroute.harness.study.workers.WorkersCannotStart: study workers: "
                           "worker processes exit while they start"), last
    assert 'if __name__ == "__main__":' in last
    assert last.endswith("or run with one worker (workers 1))"), last   # the API's keyword, not the flag
