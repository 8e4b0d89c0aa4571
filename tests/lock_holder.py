"""Another process holding a study directory's lock, as a live server or a study run does."""

from __future__ import annotations

import contextlib
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

HOLD_THE_STUDY = """
import sys
from pathlib import Path
from trustroute.harness.study.runner import study_lock
with study_lock(Path(sys.argv[1])):   # the lock `trustroute study` and `trustroute live` hold
    print("held", flush=True)
    sys.stdin.read()
"""


@contextlib.contextmanager
def another_process_holds(study: Path) -> Iterator[int]:
    """A second Python process holds `study`'s lock until the block ends; yields its pid."""
    holder = subprocess.Popen([sys.executable, "-c", HOLD_THE_STUDY, str(study)],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        yield holder.pid
    finally:
        holder.communicate("", timeout=60)
