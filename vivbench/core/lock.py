"""An exclusive lock on an output directory, so two runs never write one directory at once."""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

from vivbench.core.errors import InputError

__all__ = ["exclusive_directory"]


@contextmanager
def exclusive_directory(out: Path, lock_name: str, what: str):
    """Hold ``out/lock_name`` for the duration; a second holder gets one-line ``InputError``.

    Parameters
    ----------
    out : Path
        The output directory (must exist).
    lock_name : str
        File name of the lock inside ``out``, e.g. ``".sweep.lock"``.
    what : str
        The kind of run, for the message: ``"{out}: another {what} is writing to this directory"``.
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX: no lock
        yield
        return
    fh = (Path(out) / lock_name).open("a")
    try:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise InputError(f"{out}: another {what} is writing to this directory") from None
        yield
    finally:
        fh.close()
