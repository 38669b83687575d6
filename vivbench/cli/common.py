"""Helpers shared by the subcommands: argument types, progress bars, event paths."""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path
from vivbench.core.errors import InputError

DEFAULT_WORKERS = min(2, os.cpu_count() or 1)


def duration(text: str) -> tuple[float, float]:
    """'40' or '20-60' (minutes) -> (min, max) seconds."""
    try:
        parts = [float(p) for p in text.split("-")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"duration must be MINUTES or MIN-MAX minutes, e.g. 40 or 20-60; got {text!r}") from None
    if len(parts) == 1:
        parts = parts * 2
    if len(parts) != 2 or parts[0] <= 0 or parts[1] < parts[0]:
        raise argparse.ArgumentTypeError(f"duration must be MINUTES or MIN-MAX minutes with 0 < MIN <= MAX; got {text!r}")
    return parts[0] * 60.0, parts[1] * 60.0


def progress(total: int, desc: str, unit: str = "event"):
    """A tqdm bar on stderr (silent when stderr is not a terminal and tqdm decides so)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, disable=None)


def run_resumable(command: str, total: int, unit: str, saved: str, call):
    """``call(advance)`` under a progress bar, ``advance(n_done, n_total)`` moving it.

    Returns ``call``'s value, or None after Ctrl-C, which ends with one line on stderr saying that
    ``saved`` (what was kept) lets the same command resume.
    """
    bar = progress(total, command, unit=unit)

    def advance(done: int, _total: int) -> None:
        bar.update(done - bar.n)

    try:
        return call(advance)
    except KeyboardInterrupt:
        bar.close()
        print(f"vivbench {command}: interrupted; {saved}: run the same command again to resume", file=sys.stderr)
        return None
    finally:
        bar.close()


def event_paths(inputs: list[str]) -> list[Path]:
    """Expand campaign directories into their event files; keep files as given."""
    from vivbench.io.event import list_events

    paths: list[Path] = []
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            found = list_events(p)
            if not found:
                raise InputError(f"{p}: no event files (<event_id>.nc) in this directory")
            paths.extend(found)
        else:
            paths.append(p)
    return paths


def write_command(out_dir, argv: list[str]) -> None:
    """Write ``vivbench ARGV`` (shell-quoted) to ``out_dir/command.txt``: the report cites it."""
    from vivbench.io.netcdf import atomic_path

    with atomic_path(Path(out_dir) / "command.txt") as tmp:
        tmp.write_text(f"vivbench {shlex.join(argv)}\n")


def record_command(out_dir, args) -> None:
    """:func:`write_command` with the parsed invocation's arguments, if ``out_dir`` exists."""
    argv = getattr(args, "argv", None)
    if argv is not None and Path(out_dir).is_dir():
        write_command(out_dir, argv)


def renamed_option(parser: argparse.ArgumentParser, old: str, new: str) -> None:
    """Refuse the former option ``old`` with a one-line error naming ``new`` (exit 2); hidden from ``--help``."""

    class _Renamed(argparse.Action):
        def __call__(self, parser, namespace, values, option_string=None):
            parser.error(f"{old} is now named {new}")

    parser.add_argument(old, action=_Renamed, nargs="?", help=argparse.SUPPRESS)
