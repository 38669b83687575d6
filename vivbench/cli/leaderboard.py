"""``vivbench leaderboard``: every method scored on every scenario of the suite; resumable."""

from __future__ import annotations

import sys
from pathlib import Path

from vivbench.cli.common import DEFAULT_WORKERS, progress, record_command


def run(args) -> int:
    from vivbench.validate import load_scenario_file, parse_methods, run_leaderboard, select_scenarios

    methods = parse_methods(args.methods)
    if args.family is not None:
        from vivbench.core.errors import InputError
        from vivbench.validate.scenarios import family_scenarios
        from vivbench.validate.study import parse_draws

        if args.scenarios or args.scenario_file:
            raise InputError("--family replaces the scenarios: give it without --scenarios and --scenario-file")
        if not args.draws:
            raise InputError("--family needs --draws (e.g. 0-6)")
        scenarios = family_scenarios(args.family, parse_draws(args.draws))
    else:
        extra = load_scenario_file(args.scenario_file) if args.scenario_file else None
        scenarios = select_scenarios(args.scenarios, extra)
    bar = progress(len(scenarios) * (1 + len(methods)), "leaderboard", unit="task")
    try:
        result = run_leaderboard(methods, scenarios, args.out, workers=args.workers, scheduler=args.scheduler,
                                 rerun=parse_methods(args.rerun) if args.rerun else (),
                                 progress=lambda *_: bar.update())
    except KeyboardInterrupt:
        bar.close()
        print(f"vivbench leaderboard: interrupted; finished cells are saved under {Path(args.out) / 'cells'}: "
              "run the same command again to resume", file=sys.stderr)
        return 130
    finally:
        bar.close()
    record_command(args.out, args)
    for what, message in result.failures.items():
        print(f"vivbench leaderboard: {what}: {message}", file=sys.stderr)
    notes = []
    if result.resumed:
        notes.append(f"{len(result.resumed)} resumed")
    reused = len(scenarios) - len(result.prepared)
    if reused:
        notes.append(f"{reused} scenario campaign(s) reused")
    extra_text = f" ({'; '.join(notes)})" if notes else ""
    print(f"leaderboard: {len(scenarios)} scenarios x {len(methods)} methods, {len(result.computed)} cells computed, "
          f"{len(result.failures)} failed{extra_text}")
    print(f"wrote {result.table}, {result.markdown} and {result.figure}")
    return 1 if result.failures else 0


def register(sub) -> None:
    s = sub.add_parser("leaderboard",
                       help="score methods on the scenario suite (writes leaderboard.csv/.md/.png); resumable")
    s.add_argument("--methods", required=True,
                   help="comma-separated methods: windows, pooled, varying, pysindy-cp, binned, greybox (the "
                        "grey-box refit given each scenario bridge's structural properties), or package.module:factory "
                        "(a factory takes no arguments and returns a method with fit(records))")
    s.add_argument("--scenarios", default=None,
                   help="comma-separated scenario names (default: the whole suite: in_library, realistic, "
                        "other_bridge, forced_only, drift, high_noise, dropouts)")
    s.add_argument("--scenario-file", default=None, metavar="TOML",
                   help="user-defined scenarios ([scenario.NAME] tables: version, description, events, duration, "
                        "seed, in_class, [scenario.NAME.generator]); without --scenarios they replace the suite")
    s.add_argument("--family", default=None, choices=("development", "evaluation"),
                   help="rank on draws of the generator family instead of the suite: evaluation draws, which no "
                        "one may tune on, so a method cannot be tuned on the campaigns it is ranked on (with "
                        "--draws)")
    s.add_argument("--draws", default=None, help="with --family: draw numbers, N, N-M or a comma-separated list")
    s.add_argument("--out", required=True,
                   help="output directory; rerunning into it resumes and reuses the scenarios' campaigns")
    s.add_argument("--rerun", default=None, metavar="METHODS",
                   help="comma-separated methods (among --methods) whose finished cells are computed again: cells "
                        "are keyed by scenario and method spec, not by the method's code, so rerun a method you changed")
    s.add_argument("--workers", type=int, default=DEFAULT_WORKERS,
                   help="local worker processes (the scores do not depend on it; fit times do)")
    s.add_argument("--scheduler", default=None,
                   help="dask: local:N starts a local cluster of N processes; or a scheduler address tcp://HOST:PORT "
                        "(OUT must then be on a file system the workers share)")
    s.set_defaults(func=run)
