"""The ``vivbench`` command line: parse, build the configuration, call the library.

One module per subcommand, each with ``register(subparsers)`` that adds its
parser and sets ``func``. Progress bars go to stderr. Exit statuses::

    0    success.
    1    some files or tasks failed (each reported on one line, the others
         finished), or an internal error: a bug in vivbench. A bug prints its
         traceback and then one line ``vivbench <cmd>: internal error (<Type>:
         <message>); this is a bug in vivbench <version>: please report it ...``.
    2    bad input (:class:`vivbench.core.errors.InputError`: a file, a
         configuration or command-line value, data that cannot be used) or an
         ``OSError`` (missing file, permission, full disk): one line
         ``vivbench <cmd>: <file>: <problem>`` on stderr. argparse's own usage
         errors also exit 2.
    130  interrupted (Ctrl-C).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback

__all__ = ["main", "EXIT_FAILED", "EXIT_INPUT", "EXIT_INTERNAL", "EXIT_INTERRUPTED"]

EXIT_FAILED = 1  # some files or tasks failed; the subcommand reported each
EXIT_INTERNAL = 1  # a bug: traceback and a request to report it
EXIT_INPUT = 2  # bad input or an OSError: one line
EXIT_INTERRUPTED = 130

# Order of appearance in ``vivbench --help``.
_COMMANDS = ("synth", "import_", "events", "identify", "pool", "cluster", "forecast", "refit", "greybox", "validate", "compare", "leaderboard", "sweep", "study", "twin", "plot_event", "report", "demo")


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
    from vivbench.core.errors import InputError

    try:
        return args.func(args)
    except (InputError, OSError) as exc:  # the user's input or environment (EventFormatError is an InputError)
        message = " ".join(str(exc).split())
        print(f"vivbench {args.command}: {message}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        print(f"vivbench {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:  # noqa: BLE001 - anything else is a bug in vivbench
        traceback.print_exc(file=sys.stderr)
        print(_internal_error_line(args.command, exc), file=sys.stderr)
        return EXIT_INTERNAL


def _internal_error_line(command: str, exc: BaseException) -> str:
    import vivbench

    message = " ".join(str(exc).split())
    return (f"vivbench {command}: internal error ({type(exc).__name__}: {message}); this is a bug in vivbench "
            f"{vivbench.__version__}: please report it with the command line and the traceback above")
