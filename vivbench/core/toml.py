"""Reading TOML configuration files with one-line errors that name the file."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar
from vivbench.core.errors import InputError

__all__ = ["load_toml"]

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

T = TypeVar("T")


def load_toml(path, build: Callable[[dict], T], what: str = "configuration file") -> T:
    """Parse ``path`` and build a configuration from its dict.

    Raises
    ------
    InputError
        ``<path>: no such <what>`` or ``<path>: <problem>`` for bad TOML or a
        configuration that ``build`` refuses.
    """
    path = Path(path)
    try:
        with path.open("rb") as fh:
            data = tomllib.load(fh)
        return build(data)
    except FileNotFoundError:
        raise InputError(f"{path}: no such {what}") from None
    except (tomllib.TOMLDecodeError, ValueError, TypeError) as exc:
        raise InputError(f"{path}: {exc}") from None
