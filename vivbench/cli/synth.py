"""``vivbench synth``: generate a synthetic campaign."""

from __future__ import annotations

import sys

from vivbench.cli.common import DEFAULT_WORKERS, duration, progress
from vivbench.core.errors import InputError


def run(args) -> int:
    from vivbench.synth import CampaignConfig, GeneratorConfig, generate_campaign, load_config

    if args.family is not None:
        return _family(args)
    if args.draw is not None or args.max_events is not None or args.max_duration is not None:
        raise InputError("--draw, --max-events and --max-duration go with --family")
    if args.scenario:
        given = [f"--{k}" for k in ("config", "mode", "events", "seed", "duration") if getattr(args, k) is not None]
        if given:
            raise InputError(f"--scenario {args.scenario} fixes the campaign (generator, events, duration, seed); "
                             f"drop {', '.join(given)}")
        from vivbench.validate.scenarios import scenario

        campaign = scenario(args.scenario).campaign_config()
    else:
        if args.config:
            generator = load_config(args.config, mode=args.mode)
        else:
            generator = GeneratorConfig.from_mode(args.mode or "realistic")
        campaign = CampaignConfig(n_events=31 if args.events is None else args.events,
                                  seed=0 if args.seed is None else args.seed,
                                  duration=(1200.0, 3600.0) if args.duration is None else args.duration,
                                  generator=generator)
    bar = progress(campaign.n_events, "synth")
    try:
        result = generate_campaign(campaign, args.out, workers=args.workers, progress=lambda _id: bar.update())
    finally:
        bar.close()
    return _report(result, f"wrote {len(result.files)} events and {result.catalogue}")


def _report(result, done: str) -> int:
    for event_id, message in sorted(result.failures.items()):
        print(f"vivbench synth: {event_id}: {message}", file=sys.stderr)
    print(done)
    return 1 if result.failures else 0


def _family(args) -> int:
    from vivbench.synth.family import draw_bridge, generate_family_campaign

    given = [f"--{k}" for k in ("config", "mode", "events", "seed", "duration", "scenario")
             if getattr(args, k) is not None]
    if given:
        raise InputError(f"--family fixes the campaign (bridge, events, duration, seed); drop {', '.join(given)}")
    if args.draw is None:
        raise InputError("--family needs --draw N (the draw's number in the split, from 0)")
    caps = {"max_events": args.max_events,
            "max_duration": None if args.max_duration is None else args.max_duration * 60.0}
    bar = progress(draw_bridge(args.family, args.draw).campaign_config(**caps).n_events, "synth")
    try:
        result, described = generate_family_campaign(args.family, args.draw, args.out, workers=args.workers,
                                                     progress=lambda _id: bar.update(), **caps)
    finally:
        bar.close()
    return _report(result, f"wrote {len(result.files)} events, {result.catalogue} and {described}")


def _positive_int(text: str) -> int:
    import argparse

    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1; got {text!r}")
    return value


def _minutes(text: str) -> float:
    import argparse

    try:
        value = float(text)
    except ValueError:
        value = 0.0
    if not value >= 2.0:
        raise argparse.ArgumentTypeError(f"expected minutes >= 2; got {text!r}")
    return value


def register(sub) -> None:
    s = sub.add_parser("synth", help="generate a synthetic campaign (event files + catalogue.csv)")
    s.add_argument("--events", type=int, default=None, help="number of events (default 31)")
    s.add_argument("--seed", type=int, default=None, help="campaign seed (default 0)")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--duration", type=duration, default=None,
                   help="event duration in minutes: N or MIN-MAX (default 20-60)")
    s.add_argument("--config", help="generator configuration (TOML); the --mode defaults otherwise")
    s.add_argument("--mode", choices=("realistic", "in_library"), default=None,
                   help="generator mode (docs/concepts.md (no inverse crime)): realistic (the default: non-polynomial functions of reduced "
                        "velocity with a yaw factor, the deck feels the tributary-averaged wind of a spatially "
                        "resolved field; the truth lies outside the identification's model class) or in_library "
                        "(polynomial aerodynamics in U, the deck feels the anemometer's wind; the truth has an exact "
                        "coefficient matrix, for exact-recovery checks). Replaces the --config file's top-level "
                        "`mode` (realistic when the file has none); the file's explicit keys override the mode's "
                        "values. Slow changes stay off in both (the [changes] table)")
    s.add_argument("--scenario", default=None, metavar="NAME",
                   help="a named scenario of the leaderboard suite (vivbench.validate.SCENARIOS: in_library, realistic, "
                        "other_bridge, forced_only, drift, high_noise, dropouts): its fixed generator, events, "
                        "duration and seed; not combined with --config, --mode, --events, --seed or --duration")
    s.add_argument("--family", choices=("development", "evaluation"), default=None,
                   help="a bridge of the generator family (wide priors over bridges and physics variants): its "
                        "development draws may be used to choose anything, its evaluation draws only to report; "
                        "with --draw N; writes family.json (what was drawn) beside the events")
    s.add_argument("--draw", type=int, default=None, metavar="N", help="the family draw's number (from 0)")
    s.add_argument("--max-events", type=_positive_int, default=None,
                   help="with --family: at most this many events (a smaller campaign than the draw's, for quick "
                        "checks; recorded in family.json)")
    s.add_argument("--max-duration", type=_minutes, default=None, metavar="MINUTES",
                   help="with --family: events at most this long (recorded in family.json)")
    s.add_argument("--workers", type=int, default=DEFAULT_WORKERS, help="worker processes (files do not depend on it)")
    s.set_defaults(func=run)
