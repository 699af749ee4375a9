"""Writing output files so that a failure leaves nothing that looks finished, and nothing behind.

Every output (artifacts, videos, images) is encoded in memory first and then written here: to a
temporary name beside the target, renamed over it when complete. The disk is touched only by
plain Python writes, so a full disk or a read-only folder is one OSError, turned into one
paragraph that names the file and the cause (HDF5 writing to a full disk itself segfaulted).
A temporary file left by a killed program (SIGKILL cannot be caught) is removed by the next run
that writes the same output.
"""
from __future__ import annotations

import errno
import os
import socket
from pathlib import Path
from typing import Iterable

from .program import InputError

_HOST = socket.gethostname().replace("-", "_")


def partial_name(path: Path, pid: int | None = None) -> Path:
    """The temporary file of ``path`` written by process ``pid`` (this one by default) on this host."""
    return path.with_name(f".{path.name}.partial-{_HOST}-{os.getpid() if pid is None else pid}")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    return True


def remove_stale_partials(path: Path) -> list[Path]:
    """Remove the temporary files of ``path`` left by processes of this host that no longer run."""
    removed = []
    for tmp in path.parent.glob(f".{path.name}.partial-{_HOST}-*"):
        pid = tmp.name.rsplit("-", 1)[1]
        if pid.isdigit() and int(pid) != os.getpid() and not _alive(int(pid)):
            try:
                tmp.unlink()
                removed.append(tmp)
            except OSError:
                pass  # the write that follows reports what is wrong with the folder
    return removed


def _unwritable(path: Path, err: OSError) -> InputError:
    """The one-paragraph error of a write to ``path`` that failed with ``err``."""
    fixes = {errno.ENOSPC: "free space on that file system or write the output elsewhere",
             errno.EDQUOT: "free space within your quota or write the output elsewhere",
             errno.EROFS: "the file system is mounted read-only: write the output elsewhere",
             errno.EACCES: "make the folder writable for you or write the output elsewhere",
             errno.EPERM: "make the folder writable for you or write the output elsewhere"}
    return InputError(path, None, f"cannot write this output: {err.strerror or err}",
                      fixes.get(err.errno, "check the folder and its file system, or write the output elsewhere"))


def check_writable(outputs: Iterable[Path | str]) -> None:
    """Before any work: create each output's folder, remove stale temporary files and try a write there.

    Raises:
        InputError: a folder cannot be created or written (read-only, permissions), naming it.
    """
    for path in map(Path, outputs):
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            remove_stale_partials(path)
            probe = partial_name(path)
            probe.write_bytes(b"")
            probe.unlink()
        except OSError as err:
            raise _unwritable(path, err) from None


def write_file(path: Path | str, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically: a temporary file beside it, renamed when complete.

    Raises:
        InputError: the disk is full, the folder read-only or not writable; no temporary file is left.
    """
    import shutil

    path = Path(path)
    tmp = partial_name(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_partials(path)
        usage = shutil.disk_usage(path.parent)
        if 0 < usage.total and usage.free < len(data):  # (some FUSE file systems report no sizes at all)
            raise OSError(errno.ENOSPC, f"No space left on device ({len(data) / 1e6:.1f} MB needed, "
                          f"{usage.free / 1e6:.1f} MB free)")
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException as err:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass  # a read-only folder refuses even this; the first error is the one to report
        if isinstance(err, OSError):
            raise _unwritable(path, err) from None
        raise
    return path


def same_file(a: Path | str, b: Path | str) -> bool:
    """Whether two paths name one file (existing or not)."""
    a, b = Path(a), Path(b)
    if a.exists() and b.exists():
        return os.path.samefile(a, b)
    return a.resolve() == b.resolve()


def refuse_overwriting(outputs: dict[str, Path], inputs: dict[str, Path]) -> None:
    """An InputError when an output flag names a folder, an input file or another output.

    Args:
        outputs, inputs: flag (e.g. "--out") -> path.
    """
    seen = list(inputs.items())
    for flag, path in outputs.items():
        if Path(path).is_dir() and flag.startswith("-"):
            raise InputError(path, flag, f"{flag} names a folder, where this program writes a file",
                             f"give {flag} the path of the file to write, such as {Path(path) / Path(path).name}")
        if Path(path).is_dir():  # a file the program names itself, beside its output
            raise InputError(path, flag, f"a folder stands where this program writes {flag}",
                             "move that folder away, or give the output another folder")
        for other, given in seen:
            if given is not None and same_file(path, given):
                raise InputError(path, flag, f"{flag} names the same file as {other}, which this program "
                                 f"{'reads' if other in inputs else 'also writes'}",
                                 f"give {flag} another path")
        seen.append((flag, path))
