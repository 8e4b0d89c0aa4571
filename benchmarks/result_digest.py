"""Digests of the results a refactoring must leave unchanged, bit for bit.

`python -m benchmarks.result_digest OUT.json` runs, through the `trustroute` command only (so it
reads any version of the package the same way):
- synthesis of phi1, phi2 and their strict variants at H = 20 and unbounded, the trust-state
  spec at H = 10 and the three-type robust policy at H = 10: bounds and a hash of the policy
  file without its wall time;
- the exact evaluation of each of those policies;
- a seeded model-engine study and a seeded SUMO study (21 participants, phi1/phi2 x aware/free):
  a hash of every table (rows sorted, wall-time columns left out).
Every synthesis runs under a work limit (`--work-limit`, policies/work_clock.py): its phases'
shares, its predictions of what still fits and its stop are then on the work done, not the wall
clock (a bounded synthesis that converges still schedules its phases by shares of its limit, and
under load the wall clock moved them: phi2 at H = 20 gave another policy at load 9 to 16), and the
time limit, far above, is only a safety net; so no result depends on the machine's load. An entry
the wall clock cut all the same (its synthesis says `"stopped_by": "time limit"`) gets no digest: one
line names it and the fix (rerun on a quieter machine or raise its time limit), exit 2.
Two digests are compared with `python -m benchmarks.result_digest A.json B.json`; `--only PREFIX`
(repeatable) runs only the entries whose names start with a prefix (e.g. `--only phi1_H20 --only
study_model`).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.core.errors import InputError
from trustroute.core.validation import read_json

REPO = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "trustroute"]
POPULATION = REPO / "participants" / "data" / "driver_population_three_types.json"
TIMED = ("seconds", "wall", "elapsed", "created", "timestamp", "started", "finished", "duration")

# Units of work (`--work-limit`): an unbounded synthesis converges within 3,000,000 in about 3 s
# and the robust one's 19 runs share 4,000,000 in about 15 s (measured, load about 4). The time
# limits are only a safety net under the work limits, set far above them: this 2-core machine is
# shared, and at load 15 to 19 the same work took ten to fifteen times as long (6,000,000 units of
# the robust synthesis over 230 s, an unbounded one over 57 s). The bounded syntheses converge
# within the unbounded ones' work.
WORK = ["--time-limit", "600", "--work-limit", "3000000"]
ROBUST_WORK = ["--time-limit", "600", "--work-limit", "4000000"]

SYNTHESES = [
    ("phi1_H20", ["specs/phi1.toml", "--horizon", "20", *WORK]),
    ("phi2_H20", ["specs/phi2.toml", "--horizon", "20", *WORK]),
    ("phi1_strict_H20", ["specs/phi1_strict.toml", "--horizon", "20", *WORK]),
    ("phi2_strict_H20", ["specs/phi2_strict.toml", "--horizon", "20", *WORK]),
    ("phi1_unbounded", ["specs/phi1.toml", *WORK]),
    ("phi2_unbounded", ["specs/phi2.toml", *WORK]),
    ("phi1_strict_unbounded", ["specs/phi1_strict.toml", *WORK]),
    ("phi2_strict_unbounded", ["specs/phi2_strict.toml", *WORK]),
    ("phi1_trust_H10", ["specs/phi1_trust.toml", "--horizon", "10", *WORK]),
    ("phi1_strict_robust_H10", ["specs/phi1_strict.toml", "--horizon", "10", "--population",
                                str(POPULATION), "--objective", "robust", *ROBUST_WORK]),
]


def _run(args: list[str], cache: Path) -> dict:
    """The JSON answer of `trustroute ARGS --json`, run in the repository with `cache` as its cache
    root (XDG_CACHE_HOME), so that no policy or net of another tree's cache is read."""
    done = subprocess.run([*CLI, *args, "--json"], cwd=REPO, capture_output=True, text=True,
                          env={**os.environ, "PYTHONHASHSEED": "0", "XDG_CACHE_HOME": str(cache)})
    if done.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(args)}: exit {done.returncode}: {done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout)


def _untimed(value):
    if isinstance(value, str):
        return value.replace(str(REPO), "<repo>")  # the same digest from any checkout
    if isinstance(value, dict):
        return {k: _untimed(v) for k, v in value.items() if not any(t in k for t in TIMED)}
    if isinstance(value, list):
        return [_untimed(v) for v in value]
    return value


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def _policy_digest(path: Path) -> str:
    document = _untimed(json.loads(path.read_text()))
    arrays = np.load(path.with_suffix(".npz"))
    parts = [json.dumps(document, sort_keys=True).encode()]
    for name in sorted(arrays.files):
        array = arrays[name]
        parts += [name.encode(), str(array.dtype).encode(), str(array.shape).encode(), array.tobytes()]
    return _digest(b"".join(parts))


def _table_digest(path: Path) -> str:
    frame = pd.read_parquet(path)
    frame = frame[[c for c in frame.columns if not any(t in c for t in TIMED)]]
    frame = frame.reindex(sorted(frame.columns), axis=1)
    header, *rows = frame.to_csv(index=False).splitlines()
    return _digest("\n".join([header, *sorted(rows)]).encode())


def refuse_clock_cut(name: str, args: list[str], answer: dict) -> None:
    """Stop, with one line and exit 2, when the wall clock cut a synthesis run under a work limit
    (`"stopped_by": "time limit"`, policies/work_clock.py: past its time limit every deadline reads
    late, so a run, a search or an evaluation may have been cut where the work limit would not
    have): its digest would depend on the machine's load and differ silently."""
    if "--work-limit" not in args or answer["stopped_by"] != "time limit":
        return
    limit = args[args.index("--time-limit") + 1]
    error = InputError(name, "", f"the wall clock cut its synthesis under its work limit (stopped by its "
                       f"{limit} s time limit), so its result depends on the machine's load",
                       "rerun on a quieter machine or raise its time limit")
    print(error.one_line(), file=sys.stderr)
    raise SystemExit(2)


def digest(work: Path, only: list[str]) -> dict:
    """The digest of the entries `only` names (all when empty), its files and caches in `work`."""
    results: dict = {}
    cache = work / "cache"

    def wanted(name: str) -> bool:
        return not only or any(name.startswith(prefix) for prefix in only)

    for name, args in SYNTHESES:
        if not wanted(name):
            continue
        out = work / f"{name}.json"
        answer = _run(["synth", *args, "--out", str(out)], cache)
        refuse_clock_cut(name, args, answer)
        population = ["--population", str(POPULATION)] if "--population" in args else []
        evaluation = _run(["evaluate", args[0], str(out), *population], cache)
        results[name] = {
            "lower": answer["lower"], "upper": answer["upper"], "policy": _policy_digest(out),
            "evaluate": _untimed({k: v for k, v in evaluation.items() if k != "paths"}),
        }
        print(name, answer["lower"], answer["upper"], results[name]["policy"], answer.get("stopped_by", ""),
              file=sys.stderr)
    for engine in ("model", "sumo"):
        if not wanted(f"study_{engine}"):
            continue
        config = work / f"{engine}.toml"
        config.write_text(
            "[study]\nparticipants = 21\nseed = 1\n"
            f'engine = "{engine}"\nspecs = ["phi1", "phi2"]\nconditions = ["aware", "free"]\n'
        )
        study_dir = work / f"study_{engine}"
        _run(["study", str(config), "--out", str(study_dir), "--workers", "2", "--quiet"], cache)
        results[f"study_{engine}"] = {
            str(p.relative_to(study_dir)): _table_digest(p) for p in sorted(study_dir.rglob("*.parquet"))
            if not p.parent.name.startswith("part")
        }
        print(engine, results[f"study_{engine}"], file=sys.stderr)
    return results


def read_digest(path: Path) -> dict:
    """A digest this module wrote, read as every JSON input is (trustroute/core/validation.py); a
    file that is not one ends the command with one line (exit 2)."""
    fix = "give a file `python -m benchmarks.result_digest OUT.json` wrote"
    try:
        results = read_json(path, "digest", fix=fix)
        if not isinstance(results, dict):
            raise InputError(str(path), "", "not a digest (an object of entries)", fix)
    except InputError as error:
        print(error.one_line(), file=sys.stderr)
        raise SystemExit(2) from None
    return results


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.result_digest",
        description="OUT.json: write the digest of this tree's results; A.json B.json: compare two "
                    "digests (exit 1 if they differ).")
    parser.add_argument("paths", nargs="+", metavar="JSON")
    parser.add_argument("--only", action="append", default=[], metavar="PREFIX",
                        help="run only the entries whose names start with PREFIX (repeatable); "
                             "comparing, 'common' compares only the entries both digests have")
    args = parser.parse_args(argv)
    if len(args.paths) > 2:
        parser.error("give OUT.json, or A.json B.json")
    if len(args.paths) == 2:
        a, b = (read_digest(Path(p)) for p in args.paths)
        keys = sorted((set(a) & set(b)) if args.only == ["common"] else (set(a) | set(b)))
        differing = [k for k in keys if a.get(k) != b.get(k)]
        print("identical" if not differing else f"differ: {differing}")
        raise SystemExit(1 if differing else 0)
    with tempfile.TemporaryDirectory() as tmp:
        results = digest(Path(tmp), args.only)
    Path(args.paths[0]).write_text(json.dumps(results, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
