"""Run every benchmark module and print one JSON object per line.

Usage: python -m benchmarks [NAME_SUBSTRING ...]
"""

from __future__ import annotations

import importlib
import json
import pkgutil
import sys
import traceback

import benchmarks


def main(argv: list[str]) -> int:
    names = sorted(m.name for m in pkgutil.iter_modules(benchmarks.__path__)
                   if m.name.startswith("bench_"))
    if argv:
        names = [n for n in names if any(a in n for a in argv)]
    failed = 0
    for name in names:
        try:
            module = importlib.import_module(f"benchmarks.{name}")
            for result in module.run():
                print(json.dumps(result), flush=True)
        except Exception as exc:  # a broken benchmark must not hide the others
            failed += 1
            print(json.dumps({"name": name, "error": f"{type(exc).__name__}: {exc}"}), flush=True)
            traceback.print_exc(file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
