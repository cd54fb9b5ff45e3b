"""Writing an output file so that a failure never leaves a half-written file that looks complete.

:func:`atomic_output` opens a temporary file beside the target (same directory, so the rename is
atomic), hands it out, and renames it over the target only when the block ends without an error; on
any error the temporary file is removed and the target is left as it was.  An ``OSError`` (a full
disk, a directory that cannot be written, ``/dev/full``) becomes an :class:`OutputError` whose message
names the target and the reason, for a command to print as it is.

A target that is not a regular file (``/dev/full``, ``/dev/stdout``, a named pipe) cannot be renamed
over: it is written in place, and a write error still becomes an :class:`OutputError`.  This module
sits outside the layers (standard library only), so any of them can use it.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Iterator
from typing import IO, Any, Literal, overload

__all__ = ["OutputError", "atomic_output"]


class OutputError(OSError):
    """An output file cannot be written; the message names it and says why."""

    def __init__(self, path: str, reason: str) -> None:
        super().__init__(f"cannot write {path}: {reason}")
        self.path = path
        self.reason = reason

    def __str__(self) -> str:
        return f"cannot write {self.path}: {self.reason}"


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc) or type(exc).__name__


def _is_special(path: str) -> bool:
    try:
        return not stat.S_ISREG(os.stat(path).st_mode)
    except OSError:
        return False


@overload
def atomic_output(
    path: str | os.PathLike[str], mode: Literal["wb"]
) -> contextlib.AbstractContextManager[IO[bytes]]: ...
@overload
def atomic_output(
    path: str | os.PathLike[str], mode: Literal["w"] = "w"
) -> contextlib.AbstractContextManager[IO[str]]: ...
def atomic_output(
    path: str | os.PathLike[str], mode: str = "w"
) -> contextlib.AbstractContextManager[IO[Any]]:
    """A file to write ``path`` through: renamed into place when the block ends cleanly (see the module)."""
    return _atomic(os.fspath(path), mode)


@contextlib.contextmanager
def _atomic(path: str, mode: str) -> Iterator[IO[Any]]:
    encoding = None if "b" in mode else "utf-8"
    if _is_special(path):
        try:
            with open(path, mode, encoding=encoding) as f:
                yield f
        except OSError as exc:
            if isinstance(exc, OutputError):
                raise
            raise OutputError(path, _reason(exc)) from exc
        return
    folder = os.path.dirname(os.path.abspath(path))
    try:
        fd, temp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".part", dir=folder)
    except OSError as exc:
        raise OutputError(path, _reason(exc)) from exc
    try:
        with os.fdopen(fd, mode, encoding=encoding) as f:
            yield f
        _keep_mode(path, temp)
        os.replace(temp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(temp)
        if isinstance(exc, OSError) and not isinstance(exc, OutputError):
            raise OutputError(path, _reason(exc)) from exc
        raise


def _keep_mode(path: str, temp: str) -> None:
    """The new file gets the old one's permissions, or the ones a plain ``open`` would give."""
    try:
        mode = stat.S_IMODE(os.stat(path).st_mode)
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        mode = 0o666 & ~umask
    with contextlib.suppress(OSError):
        os.chmod(temp, mode)
