"""The ``vivbench`` command line: parse, build the configuration, call the library.

One module per subcommand, each with ``register(subparsers)`` that adds its
parser and sets ``func``. Every subcommand exits 0 on success and, on bad
input, prints one line ``vivbench <cmd>: <file>: <problem>`` to stderr and
exits 2. Progress bars go to stderr.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

__all__ = ["main"]

# Order of appearance in ``vivbench --help``.
_COMMANDS = ("synth", "import_", "identify", "pool", "cluster", "forecast", "refit", "validate", "compare", "sweep", "plot_event", "report", "demo")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vivbench", description="Time-varying SINDy testbed for bridge VIV.")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in _COMMANDS:
        importlib.import_module(f"vivbench.cli.{name}").register(sub)
    return p


def _single_threaded_blas() -> None:
    # The chain solves thousands of tiny least-squares problems, which threaded
    # BLAS makes about 10x slower on small machines; a user's explicit setting wins.
    # Takes effect only before numpy is first imported (the subcommands import it lazily).
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")


def main(argv: list[str] | None = None) -> int:
    _single_threaded_blas()
    args = _parser().parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    from vivbench.io.event import EventFormatError

    try:
        return args.func(args)
    except (EventFormatError, ValueError, OSError) as exc:
        message = " ".join(str(exc).split())
        print(f"vivbench {args.command}: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"vivbench {args.command}: interrupted", file=sys.stderr)
        return 130
