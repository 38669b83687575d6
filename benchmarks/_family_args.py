"""The command-line options shared by the studies over draws of the generator family."""

from __future__ import annotations

import argparse
from pathlib import Path


def family_parser(description: str, *, draws_help: str = "N, N-M or a comma-separated list",
                  max_events: int | None = None, max_duration: float | None = None) -> argparse.ArgumentParser:
    """A parser with ``--split``, ``--draws``, ``--out`` (the resumable study directory), the campaigns'
    caps ``--max-events`` and ``--max-duration`` (minutes; defaults as given) and ``--workers``."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--split", required=True, choices=("development", "evaluation"))
    parser.add_argument("--draws", required=True, help=draws_help)
    parser.add_argument("--out", required=True, type=Path, help="study directory (resumable)")
    parser.add_argument("--max-events", type=int, default=max_events)
    parser.add_argument("--max-duration", type=float, default=max_duration, metavar="MINUTES")
    parser.add_argument("--workers", type=int, default=1)
    return parser
