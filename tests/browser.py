"""The one rule of the browser tests: they drive Debian's Chromium (never a downloaded browser)
and never skip. Without it they fail with one line that says what to install; `make test`
installs it first where it can (Makefile, `browser`)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

DEBIAN_CHROMIUM = "/usr/bin/chromium"
INSTALL = "apt-get install -y chromium"


def chromium_executable() -> str:
    """The path of Debian's Chromium, or a test failure naming the install."""
    if Path(DEBIAN_CHROMIUM).is_file():
        return DEBIAN_CHROMIUM
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found is None:
        pytest.fail(f"Chromium is missing: install Debian's package ({INSTALL}); "
                    "the browser tests never download a browser", pytrace=False)
    return found
