"""``vivbench twin`` and ``vivbench twin-check``: a synthetic twin of a campaign, and whether twins predict."""

from __future__ import annotations

import sys
from pathlib import Path

from vivbench.cli.common import DEFAULT_WORKERS, record_command, run_resumable


def run(args) -> int:
    from vivbench.validate.twin import TwinConfig, run_twin
    from vivbench.validate.twin_mirror import read_bridge

    bridge = read_bridge(args.bridge)  # a bad or missing file is reported before anything runs
    config = TwinConfig(n_draws=args.draws, seed=args.seed, knot_step=args.knot_step, max_events=args.max_events,
                        **({"priors": None} if args.fixed_nuisances else {}))
    saved = f"the finished draws are saved in {Path(args.out) / 'twin.jsonl'}"
    result = run_resumable("twin", config.n_draws, "draw", saved,
                           lambda advance: run_twin(args.campaign, args.results, bridge, args.out, config=config,
                                                    model_dir=args.model, workers=args.workers, progress=advance))
    if result is None:
        return 130
    record_command(args.out, args)
    for draw, message in sorted(result.failures.items()):
        print(f"vivbench twin: draw {draw}: {message}", file=sys.stderr)
    print(f"twin: {config.n_draws} draws, {len(result.computed)} computed, {len(result.resumed)} resumed, "
          f"{len(result.failures)} failed; summary {result.summary}; page {result.page}")
    return 1 if result.failures else 0


def run_check(args) -> int:
    from vivbench.validate.study import parse_draws
    from vivbench.validate.twin_check import TwinCheckConfig, run_twin_check

    config = TwinCheckConfig(split=args.split, draws=parse_draws(args.draws), n_twins=args.twins,
                             max_events=args.max_events, bootstrap=args.bootstrap,
                             max_duration=None if args.max_duration is None else args.max_duration * 60.0)
    saved = f"the finished draws are saved in {Path(args.out)}"
    outcome = run_resumable("twin-check", len(config.draws), "draw", saved,
                            lambda advance: run_twin_check(config, args.out, workers=args.workers, progress=advance))
    if outcome is None:
        return 130
    path, page, failures = outcome
    record_command(args.out, args)
    for draw, message in sorted(failures.items()):
        print(f"vivbench twin-check: draw {draw}: {message}", file=sys.stderr)
    print(f"twin-check: summary {path}; page {page}")
    return 1 if failures else 0


def register(sub) -> None:
    s = sub.add_parser("twin", help="a synthetic twin of a campaign: the chain rerun on synthetic campaigns that "
                                    "mirror it, for the expected recovery on this bridge (twin.json, twin.md)")
    s.add_argument("campaign", help="the campaign's event files (directory of <event_id>.nc)")
    s.add_argument("results", help="their identification results (directory of <event_id>.identify.nc)")
    s.add_argument("--bridge", required=True, metavar="FILE",
                   help="TOML with the bridge's structural properties ([bridge] mass, depth, damping_ratio; "
                        "optionally frequency, mode_shape, tributary_lengths, air_density, span_length)")
    s.add_argument("--model", default=None, metavar="DIR",
                   help="where vivbench pool wrote campaign.model.nc and campaign.regimes.nc (default: RESULTS)")
    s.add_argument("--out", required=True, help="output directory; rerunning with the same options resumes")
    s.add_argument("--draws", type=int, default=5, help="twin campaigns (default 5)")
    s.add_argument("--seed", type=int, default=0, help="seed of the twin draws (default 0)")
    s.add_argument("--knot-step", type=float, default=120.0,
                   help="spacing of the mirrored mean wind's knots, s (default 120)")
    s.add_argument("--max-events", type=int, default=None,
                   help="mirror only the first events (quick checks; recorded in twin.json)")
    s.add_argument("--fixed-nuisances", action="store_true",
                   help="fix what the records cannot tell at the generator's defaults (tributary-averaged felt wind, "
                        "buffeting, no yaw effect) instead of drawing it per twin from the family's priors; the "
                        "twin's range then leaves it out")
    s.add_argument("--workers", type=int, default=DEFAULT_WORKERS,
                   help="local worker processes, one twin draw each (results do not depend on it)")
    s.set_defaults(func=run)

    c = sub.add_parser("twin-check", help="does the twin predict? family draws treated as field campaigns, each "
                                          "twinned and compared with its own truth (twin_check.json, .md)")
    c.add_argument("--split", default="evaluation", choices=("development", "evaluation"),
                   help="family split (default evaluation: reported only, never tuned on)")
    c.add_argument("--draws", default="0-2", help="family draws: N, N-M or a comma-separated list (default 0-2)")
    c.add_argument("--twins", type=int, default=3, help="twin draws per family draw (default 3)")
    c.add_argument("--bootstrap", type=int, default=100, help="pool's bootstrap replicates (default 100, as pool)")
    c.add_argument("--max-events", type=int, default=None, help="cap each family campaign at this many events")
    c.add_argument("--max-duration", type=float, default=None, metavar="MINUTES",
                   help="cap each event at this many minutes")
    c.add_argument("--out", required=True, help="output directory; rerunning with the same options resumes")
    c.add_argument("--workers", type=int, default=DEFAULT_WORKERS,
                   help="local worker processes, one family draw each")
    c.set_defaults(func=run_check)
