"""``vivbench study``: draws of the generator family generated, identified, and each method scored over them."""

from __future__ import annotations

import sys
from pathlib import Path

from vivbench.cli.common import DEFAULT_WORKERS, record_command, run_resumable


def run(args) -> int:
    from vivbench.validate.study import StudyConfig, parse_draws, run_study

    config = StudyConfig(split=args.split, draws=parse_draws(args.draws),
                         methods=tuple(m.strip() for m in args.methods.split(",") if m.strip()),
                         max_events=args.max_events,
                         max_duration=None if args.max_duration is None else args.max_duration * 60.0,
                         anemometer_span=_fractions(args.anemometers), wind_rule=args.wind_rule,
                         wind_source=args.wind_source, amplitude_source=args.amplitude_source)
    result = run_resumable("study", len(config.draws), "draw",
                           f"the finished draws are saved in {Path(args.out) / 'study.jsonl'}",
                           lambda advance: run_study(config, args.out, workers=args.workers, scheduler=args.scheduler,
                                                     progress=advance))
    if result is None:
        return 130
    record_command(args.out, args)
    for draw, message in sorted(result.failures.items()):
        print(f"vivbench study: draw {draw}: {message}", file=sys.stderr)
    times = [result.seconds[d] for d in result.computed if d in result.seconds]
    timing = f"; {sum(times) / len(times):.0f} s per computed draw" if times else ""
    print(f"study: {len(config.draws)} draws, {len(result.computed)} computed, {len(result.resumed)} resumed, "
          f"{len(result.failures)} failed{timing}")
    print(f"table {result.table}; summary {result.summary}; page {result.page}")
    return 1 if result.failures else 0


def _fractions(text):
    """``--anemometers``: comma-separated fractions of the span, or None."""
    from vivbench.core.errors import InputError

    if text is None:
        return None
    try:
        return tuple(float(x) for x in text.split(","))
    except ValueError:
        raise InputError(f"--anemometers must be comma-separated fractions of the span length in [0, 1] "
                         f"(e.g. 0.5 for one at mid-span); got {text!r}") from None


def register(sub) -> None:
    s = sub.add_parser("study", help="score methods over draws of the generator family (study.csv, summary.json, "
                                     "study.md); resumable")
    s.add_argument("--split", required=True, choices=("development", "evaluation"),
                   help="development draws may be used to choose anything; evaluation draws only to report")
    s.add_argument("--draws", required=True, help="draw numbers: N, N-M or a comma-separated list (e.g. 0-29)")
    s.add_argument("--methods", default="varying,pooled",
                   help="comma-separated methods (default varying,pooled: the two campaign models of vivbench pool; "
                        "greybox is the grey-box refit given each draw's structural properties; other names "
                        "as in vivbench compare, or package.module:factory)")
    s.add_argument("--out", required=True, help="output directory; rerunning with the same options resumes")
    s.add_argument("--max-events", type=int, default=None,
                   help="cap each campaign at this many events (quick checks; recorded on the results page)")
    s.add_argument("--max-duration", type=float, default=None, metavar="MINUTES",
                   help="cap each event at this many minutes (quick checks; recorded on the results page)")
    s.add_argument("--anemometers", default=None, metavar="F1,F2,...",
                   help="anemometers at these fractions of the span length instead of one per section (e.g. 0.5: "
                        "one at mid-span); each section's wind is taken from them by --wind-rule and the events "
                        "record how far (wind_distance_m_<section>)")
    s.add_argument("--wind-rule", default="nearest", choices=("nearest", "interpolation"),
                   help="with --anemometers: the wind at a section is the nearest anemometer's (default) or "
                        "interpolated between the two that bracket it")
    s.add_argument("--wind-source", default="measured", choices=("measured", "truth"),
                   help="what the methods are fitted on: the measured wind (default) or, as an oracle, the wind "
                        "the truth's dynamics sees (how much of the error comes from the errors in the wind)")
    s.add_argument("--amplitude-source", default="measured", choices=("measured", "truth"),
                   help="what the methods' amplitude and dA/dt are: the identified envelopes (default) or, as an "
                        "oracle, the truth's averaged ones (with --wind-source truth: the model class's own error)")
    s.add_argument("--workers", type=int, default=DEFAULT_WORKERS,
                   help="local worker processes, one draw each (results do not depend on it)")
    s.add_argument("--scheduler", default=None,
                   help="dask: local:N starts a local cluster of N processes; or a scheduler address tcp://HOST:PORT")
    s.set_defaults(func=run)
