"""Writing output files safely: atomic replacement, checks before work starts, locks.

- `atomic_write_bytes` / `atomic_write_text`: a temporary file in the target's folder, fsync,
  `os.replace`, then fsync of the folder, so a reader (or a rerun after a crash, a full disk or a
  kill) sees the old file or the whole new one, never a partial one; on failure or Ctrl-C the
  temporary file is removed, and a failure is an InputError (one line, exit 2) naming the path
  and the cause.
  `atomic_create_bytes` writes a file only where none exists (a hard link of the temporary file),
  so of two processes creating it at once exactly one does.
- `check_output_file` / `check_output_dir`: run before any work starts, so a command given an
  unwritable `--out` fails at once instead of after minutes of computation; `check_output_file`
  also refuses an output that is one of the command's input files or lies inside a study
  directory it reads (`check_apart`), which writing it would destroy.
- `file_lock`: an advisory `fcntl.flock` lock on a lock file (study directories, cache entries
  being filled); the lock file records its holder (pid, host, start time) for the error message.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import socket
import time
from collections.abc import Iterator, Mapping
from pathlib import Path

from trustroute.core.errors import InputError
from trustroute.core.package import check_outside_package

TEMP_PREFIX = ".tmp-"


def os_error_text(exc: OSError) -> str:
    """Short cause of an OSError, with the common ones spelt out."""
    if exc.errno == errno.ENOSPC:
        return "no space left on the device"
    if exc.errno == errno.EROFS:
        return "read-only file system"
    if exc.errno in (errno.EACCES, errno.EPERM):
        return "permission denied"
    if exc.errno == errno.EISDIR:
        return "is a directory"
    return exc.strerror or type(exc).__name__


# The fix of an OSError by its errno; {path} is the path in the way. mkdir(exist_ok=True) fails with
# EEXIST only where a non-directory stands, so EEXIST and ENOTDIR both mean "a file where a directory
# must be".
_NOT_A_DIRECTORY_FIX = "{path} must be a directory, not a file: move the file aside or pass another path"
OS_ERROR_FIXES: dict[int, str] = {
    errno.ENOTDIR: _NOT_A_DIRECTORY_FIX,
    errno.EEXIST: _NOT_A_DIRECTORY_FIX,
    errno.EISDIR: "{path} must be a file, not a directory: pass a file path",
    errno.ENOSPC: "free disk space, then rerun",
    errno.EDQUOT: "free disk space (the disk quota is used up), then rerun",
    errno.EACCES: "fix the permissions of {path} or pass a writable location, then rerun",
    errno.EPERM: "fix the permissions of {path} or pass a writable location, then rerun",
    errno.EROFS: "pass a location on a writable file system, then rerun",
}
OTHER_OS_ERROR_FIX = "check that {path} can be read and written, then rerun"


def os_error_fix(exc: OSError, path: str | Path | None = None) -> str:
    """The fix of an OSError from `OS_ERROR_FIXES`, naming `path` (default: the error's own file)
    or, when a file stands where a directory must be, that file."""
    named = path if path is not None else exc.filename
    where: object = "the path" if named is None else Path(named)
    if exc.errno == errno.ENOTDIR and isinstance(where, Path):
        where = _file_in_the_way(where)
    return OS_ERROR_FIXES.get(exc.errno or 0, OTHER_OS_ERROR_FIX).format(path=where)


def _file_in_the_way(path: Path) -> Path:
    """The nearest of `path` and its ancestors that exists and is not a directory (`path` if none)."""
    for candidate in (path, *path.parents):
        if candidate.exists() or candidate.is_symlink():
            return path if candidate.is_dir() else candidate
    return path


def write_error(path: str | Path, what: str, exc: OSError, fix: str = "") -> InputError:
    return InputError(str(path), "", f"cannot write the {what} ({os_error_text(exc)})",
                      fix or os_error_fix(exc, path))


def temp_path(path: Path) -> Path:
    return path.with_name(f"{TEMP_PREFIX}{path.name}.{os.getpid()}")


def fsync_directory(directory: Path) -> None:
    try:
        descriptor = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(descriptor)
    except OSError:
        pass  # some file systems cannot fsync a directory; the rename is still atomic
    finally:
        os.close(descriptor)


def atomic_write_bytes(path: str | Path, data: bytes, what: str, fix: str = "", sync: bool = True) -> Path:
    """Replace `path` by `data` atomically (InputError on any OS failure; no temporary file left)."""
    path = Path(path)
    move_into_place(_written_temp(path, data, what, fix, sync), path, what, fix, sync)
    return path


def atomic_create_bytes(path: str | Path, data: bytes, what: str, fix: str = "") -> bool:
    """Create `path` holding `data` atomically, only where no file of that name exists: True when
    it was created, False when one was there already (left as it was: another process may have
    created it meanwhile). A hard link of the finished temporary file, so the name appears whole
    or not at all (on a file system without hard links: the name taken empty, then filled by
    `os.replace`); InputError on any other OS failure, no temporary file left."""
    path = Path(path)
    temp = _written_temp(path, data, what, fix, True)
    try:
        try:
            os.link(temp, path)
        except OSError as exc:
            if exc.errno not in NO_HARD_LINKS:
                raise
            os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
            os.replace(temp, path)
    except FileExistsError:
        return False
    except OSError as exc:
        raise write_error(path, what, exc, fix) from None
    finally:
        with contextlib.suppress(OSError):
            temp.unlink()
    fsync_directory(path.parent)
    return True


# os.link's errors on a file system that has no hard links (FAT, some network and FUSE mounts)
NO_HARD_LINKS = frozenset({errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.ENOSYS})


def _written_temp(path: Path, data: bytes, what: str, fix: str, sync: bool) -> Path:
    """`data` in the temporary file of `path` (its folder made), flushed to disk with `sync`."""
    if path.is_dir():
        raise InputError(str(path), "", f"the {what} path is a directory", fix or "pass a file path")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise write_error(path.parent, f"folder of the {what}", exc, fix) from None
    temp = temp_path(path)
    try:
        with open(temp, "wb") as handle:
            handle.write(data)
            handle.flush()
            if sync:
                os.fsync(handle.fileno())
    except BaseException as exc:   # an OS failure, or Ctrl-C: no half-written temporary file stays
        with contextlib.suppress(OSError):
            temp.unlink()
        if isinstance(exc, OSError):
            raise write_error(path, what, exc, fix) from None
        raise
    return temp


def move_into_place(temp: Path, path: Path, what: str, fix: str = "", sync: bool = True) -> None:
    """Rename the finished temporary file `temp` onto `path` (atomic on one file system) and, with
    `sync`, make the rename durable; InputError on an OS failure, the temporary file removed."""
    try:
        os.replace(temp, path)
    except BaseException as exc:   # an OS failure, or Ctrl-C: no temporary file stays
        with contextlib.suppress(OSError):
            temp.unlink()
        if isinstance(exc, OSError):
            raise write_error(path, what, exc, fix) from None
        raise
    if sync:
        fsync_directory(path.parent)


def atomic_write_text(path: str | Path, text: str, what: str, fix: str = "", sync: bool = True) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"), what, fix, sync)


def _writable_folder(folder: Path) -> Path:
    """The nearest existing ancestor of `folder` (what mkdir would create under)."""
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return folder


Inputs = Mapping[str, str | Path | None]   # what the command reads, by the option or argument naming it


def check_output_file(path: str | Path, option: str, what: str, reads: Inputs | None = None,
                      studies: Inputs | None = None, suffix: str = ".json") -> Path:
    """Before work starts: `path` can be written as a file (not a directory, folder writable), is
    none of the files the command `reads` and lies in none of the study directories it reads.
    `suffix`: the file's usual ending, for the example path a refusal suggests."""
    path = Path(path)
    if "\x00" in str(path):
        raise InputError(option, "", f"the {what} path contains a NUL byte", "pass an ordinary path")
    check_apart(path, option, what, reads or {}, studies or {})
    check_outside_package(path, option, what)   # published read-only: its SHA256SUMS would break
    if path.is_dir():
        raise InputError(str(path), option, f"the {what} path is a directory",
                         f"pass a file path to {option}, e.g. {path / f'out{suffix}'}")
    if path.exists() and not os.access(path, os.W_OK):
        raise InputError(str(path), option, f"the {what} exists and is not writable",
                         f"pass a writable path to {option}")
    folder = _writable_folder(path.parent)
    if not folder.is_dir():
        raise InputError(str(path), option, f"{folder} is not a directory",
                         f"pass a path under a directory to {option}")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(str(path), option, f"cannot write in {folder} (permission denied or read-only)",
                         f"pass a writable path to {option}")
    if _read_only(folder):
        raise InputError(str(path), option, f"{folder} is on a read-only file system",
                         f"pass a writable path to {option}")
    return path


def check_apart(path: Path, option: str, what: str, reads: Inputs, studies: Inputs) -> None:
    """InputError when writing `path` would replace an input: it is one of the existing files in
    `reads` (the same file by any name: a symlink, a hard link, another spelling), or lies inside
    one of the study directories in `studies` (symlinks resolved)."""
    for name, given in reads.items():
        if given is not None and "\x00" not in str(given) and _same_file(path, Path(given)):
            raise InputError(str(path), option, f"the {what} would overwrite {name} {given}, which this "
                             "command reads", f"pass another path to {option}")
    where = Path(os.path.realpath(path))
    for name, given in studies.items():
        if given is not None and "\x00" not in str(given) and where.is_relative_to(os.path.realpath(given)):
            raise InputError(str(path), option, f"the {what} would be written inside the study directory "
                             f"{given} ({name}), which this command reads",
                             f"pass a path outside {given} to {option}")


def _same_file(output: Path, given: Path) -> bool:
    try:
        return os.path.samefile(output, given)
    except OSError:   # a new output, or an input that is no file (a packaged name): nothing to lose
        return False


def check_output_dir(path: str | Path, option: str, what: str) -> Path:
    """Before work starts: `path` is (or can be created as) a writable directory."""
    path = Path(path)
    if "\x00" in str(path):
        raise InputError(option, "", f"the {what} path contains a NUL byte", "pass an ordinary path")
    if path.exists() and not path.is_dir():
        raise InputError(str(path), option, f"the {what} exists and is not a directory",
                         f"pass a directory to {option}")
    check_outside_package(path, option, what)   # published read-only: its SHA256SUMS would break
    folder = _writable_folder(path)
    if not folder.is_dir():
        raise InputError(str(path), option, f"{folder} is not a directory", f"pass a directory to {option}")
    if not os.access(folder, os.W_OK | os.X_OK) or _read_only(folder):
        raise InputError(str(path), option, f"cannot write in {folder} (permission denied or read-only)",
                         f"pass a writable directory to {option}")
    return path


def _read_only(folder: Path) -> bool:
    try:
        return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except OSError:
        return False


# -- locks ----------------------------------------------------------------------------------------


def holder_record() -> dict:
    return {"pid": os.getpid(), "host": socket.gethostname(),
            "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def describe_holder(lock_path: Path) -> str:
    try:
        holder = json.loads(lock_path.read_text() or "{}")
    except (OSError, ValueError):
        holder = {}
    if not isinstance(holder, dict) or "pid" not in holder:
        return "another process"
    return f"pid {holder.get('pid')} on {holder.get('host')}, started {holder.get('started_utc')}"


@contextlib.contextmanager
def file_lock(lock_path: str | Path, what: str, wait: bool, fix: str = "") -> Iterator[None]:
    """Hold an exclusive flock on `lock_path` (created if missing). wait=False: InputError naming
    the holder when another process holds it; wait=True: block until it is free. The lock goes
    with the process (a killed holder never leaves a stale lock)."""
    lock_path = Path(lock_path)
    try:
        lock_path.parent.mkdir(parents=True, exist_ok=True)
        descriptor = os.open(lock_path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
    except OSError as exc:
        raise write_error(lock_path, f"lock file of the {what}", exc, fix) from None
    try:
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            raise InputError(str(lock_path.parent), "",
                             f"the {what} is in use by {describe_holder(lock_path)}",
                             fix or "wait for that run to finish, or stop it") from None
        with contextlib.suppress(OSError):
            os.ftruncate(descriptor, 0)
            os.pwrite(descriptor, json.dumps(holder_record()).encode(), 0)
        yield
    finally:
        os.close(descriptor)  # releases the lock
