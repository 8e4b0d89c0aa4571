"""Output files: the fix of an OS error follows its errno (one table), naming the path in the way;
an output that is an input of its command is refused before any work."""

from __future__ import annotations

import errno
import os

import pytest

from trustroute.core import output_files
from trustroute.core.errors import InputError
from trustroute.core.output_files import (
    OS_ERROR_FIXES,
    check_output_dir,
    check_output_file,
    os_error_fix,
    write_error,
)


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


@pytest.mark.parametrize("link", ["same", "symlink", "hard link", "spelling"])
def test_an_output_that_is_an_input_file_by_any_name_is_refused(tmp_path, link):
    spec = tmp_path / "spec.toml"
    spec.write_text("name = 'x'\n")
    out = {"same": spec, "symlink": tmp_path / "l.json", "hard link": tmp_path / "h.json",
           "spelling": tmp_path / "sub" / ".." / "spec.toml"}[link]
    (tmp_path / "sub").mkdir()
    if link == "symlink":
        out.symlink_to(spec)
    elif link == "hard link":
        os.link(spec, out)
    with pytest.raises(InputError) as error:
        check_output_file(out, "--out", "policy file", {"SPEC": spec, "--town": None})
    assert (error.value.source, error.value.place) == (str(out), "--out")
    assert error.value.problem == f"the policy file would overwrite SPEC {spec}, which this command reads"
    assert error.value.fix == "pass another path to --out"
    assert spec.read_text() == "name = 'x'\n"


def test_inputs_that_are_no_files_do_not_refuse_an_output(tmp_path):
    # a packaged name, a missing file (its reader says so), a new output
    out = tmp_path / "driver_model"
    reads = {"--driver": "driver_model", "--town": tmp_path / "none"}
    assert check_output_file(out, "--out", "x", reads) == out
    (tmp_path / "d.json").write_text("{}")
    assert check_output_file(tmp_path / "new.json", "--out", "x", {"--driver": tmp_path / "d.json"})


def test_an_output_inside_a_study_it_reads_is_refused_through_any_link(tmp_path):
    study = tmp_path / "study"
    (study / "parts").mkdir(parents=True)
    (tmp_path / "alias").symlink_to(study)
    for out in (study / "manifest.json", study / "parts" / "new.json", tmp_path / "alias" / "x.json"):
        with pytest.raises(InputError) as error:
            check_output_file(out, "--out", "driver model file", studies={"DIR": study})
        assert error.value.problem == (f"the driver model file would be written inside the study "
                                       f"directory {study} (DIR), which this command reads")
        assert error.value.fix == f"pass a path outside {study} to --out"
    assert check_output_file(tmp_path / "study.json", "--out", "x", studies={"DIR": study})
    with pytest.raises(InputError, match="inside the study directory"):
        check_output_file(study / "x.json", "--out", "x", studies={"DIR": tmp_path / "alias"})


def test_atomic_create_writes_a_file_only_where_none_is(tmp_path):
    """Of two writers creating one file, the first creates it whole and the second finds it there:
    False, the file as the first wrote it, no temporary file left."""
    target = tmp_path / "mark.json"
    assert output_files.atomic_create_bytes(target, b"first", "study marker")
    assert not output_files.atomic_create_bytes(target, b"second", "study marker")
    assert target.read_bytes() == b"first"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mark.json"]


def test_atomic_create_without_hard_links_takes_the_name_then_fills_it(tmp_path, monkeypatch):
    def no_links(source, target):
        raise OSError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(output_files.os, "link", no_links)
    target = tmp_path / "mark.json"
    assert output_files.atomic_create_bytes(target, b"first", "study marker")
    assert not output_files.atomic_create_bytes(target, b"second", "study marker")
    assert target.read_bytes() == b"first"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mark.json"]


def test_an_output_inside_a_package_is_refused(tmp_path):
    """A package (its config and tables folder) is published read-only: a file or folder to write
    anywhere under it is refused naming the package, before anything is written."""
    package = tmp_path / "package"
    (package / "tables").mkdir(parents=True)
    (package / "study_config.json").write_text("{}")
    for check, path in ((check_output_file, package / "model.json"), (check_output_dir, package / "a" / "b")):
        with pytest.raises(InputError, match=f"lies in the package {package}, which is published read-only"):
            check(path, "--out", "output")
    assert sorted(p.name for p in package.rglob("*")) == ["study_config.json", "tables"]
    check_output_file(tmp_path / "beside.json", "--out", "output")   # beside it: allowed
