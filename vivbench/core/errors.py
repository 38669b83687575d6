"""The error a user can fix: bad input, as opposed to a bug in vivbench.

The command line reports an :class:`InputError` (and an ``OSError``) as one
line and exits 2; any other exception is a bug and shows its traceback.
"""

from __future__ import annotations

__all__ = ["InputError", "error_line", "require"]


class InputError(ValueError):
    """Bad input from the user: a file, a configuration value, a command-line value, or data that cannot be used.

    It subclasses :class:`ValueError`, so ``except ValueError`` keeps catching it.
    The message is one line naming the file or value and what is wrong or allowed.
    """


def error_line(exc: BaseException) -> str:
    """One line ``Type: message`` for a refusal; ``internal error (Type: message)`` for anything else (a bug).

    A refusal is an :class:`InputError` (bad input) or an ``OSError`` (the user's
    files or machine); per-file and per-task failure reports use this wording.
    """
    text = f"{type(exc).__name__}: {exc}"
    if not isinstance(exc, (InputError, OSError)):
        text = f"internal error ({text})"
    return " ".join(text.split())


def require(condition: bool, message: str) -> None:
    """Raise :class:`InputError` with ``message`` (what is wrong and what is allowed) unless ``condition`` holds."""
    if not condition:
        raise InputError(message)
