"""Output files: the fix of an OS error follows its errno (one table), naming the path in the way."""

from __future__ import annotations

import errno
import os

import pytest

from trustroute.core.output_files import OS_ERROR_FIXES, os_error_fix, write_error


@pytest.mark.parametrize(("code", "words"), [
    (errno.ENOTDIR, "must be a directory, not a file"),
    (errno.EEXIST, "must be a directory, not a file"),
    (errno.EISDIR, "must be a file, not a directory"),
    (errno.ENOSPC, "free disk space"),
    (errno.EACCES, "fix the permissions"),
    (errno.EPERM, "fix the permissions"),
    (errno.EROFS, "writable file system"),
    (errno.EIO, "check that"),
])
def test_the_fix_follows_the_errno(code, words, tmp_path):
    fix = os_error_fix(OSError(code, os.strerror(code), str(tmp_path / "x")))
    assert words in fix
    assert "free disk space" not in fix or code == errno.ENOSPC
    if code in (errno.ENOTDIR, errno.EEXIST, errno.EISDIR, errno.EACCES):
        assert str(tmp_path / "x") in fix


def test_a_file_in_the_way_is_named_not_the_path_under_it(tmp_path):
    (tmp_path / "afile").write_text("")
    fix = os_error_fix(OSError(errno.ENOTDIR, "Not a directory", str(tmp_path / "afile" / "sub" / "x.json")))
    assert fix.startswith(f"{tmp_path / 'afile'} must be a directory")


def test_an_error_without_a_file_still_gets_a_fix():
    assert os_error_fix(OSError(errno.ENOTDIR, "Not a directory")).startswith("the path must be")
    assert "then rerun" in os_error_fix(OSError("no errno"))


def test_write_errors_without_a_fix_of_their_own_use_the_table(tmp_path):
    error = write_error(tmp_path / "t.json", "town file", OSError(errno.EISDIR, "Is a directory"))
    assert error.fix == OS_ERROR_FIXES[errno.EISDIR].format(path=tmp_path / "t.json")
    assert write_error(tmp_path, "x", OSError(errno.ENOSPC, "full"), "pass --out").fix == "pass --out"
