"""The ``vivbench`` command line: parse, build the configuration, call the library.

Every subcommand exits 0 on success and, on bad input, prints one line
``vivbench <cmd>: <file>: <problem>`` to stderr and exits 2. Progress bars go
to stderr.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

__all__ = ["main"]


class _UsageError(Exception):
    pass


def _duration(text: str) -> tuple[float, float]:
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


def _progress(total: int, desc: str):
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit="event", file=sys.stderr, disable=None)
    return bar


def _cmd_synth(args) -> int:
    from vivbench.synth import CampaignConfig, GeneratorConfig, generate_campaign, load_config

    generator = load_config(args.config) if args.config else GeneratorConfig()
    campaign = CampaignConfig(n_events=args.events, seed=args.seed, duration=args.duration, generator=generator)
    bar = _progress(campaign.n_events, "synth")
    try:
        result = generate_campaign(campaign, args.out, workers=args.workers, progress=lambda _id: bar.update())
    finally:
        bar.close()
    for event_id, message in sorted(result.failures.items()):
        print(f"vivbench synth: {event_id}: {message}", file=sys.stderr)
    print(f"wrote {len(result.files)} events and {result.catalogue}")
    return 1 if result.failures else 0


def _cmd_plot_event(args) -> int:
    from vivbench.io import read_event
    from vivbench.report import event_figure

    tree = read_event(args.event)
    out = event_figure(tree, args.out, section=args.section)
    print(f"wrote {out}")
    return 0


def _cmd_demo(args) -> int:
    from vivbench.io import read_event
    from vivbench.report import event_figure
    from vivbench.synth import CampaignConfig, generate_campaign

    out = Path(args.out)
    campaign = CampaignConfig(seed=args.seed)
    bar = _progress(campaign.n_events, "synth")
    try:
        result = generate_campaign(campaign, out / "campaign", workers=args.workers, progress=lambda _id: bar.update())
    finally:
        bar.close()
    if result.failures:
        for event_id, message in sorted(result.failures.items()):
            print(f"vivbench demo: {event_id}: {message}", file=sys.stderr)
        return 1
    figure = event_figure(read_event(result.files[0]), out / "event_E001.png")
    print(f"campaign: {len(result.files)} events in {out / 'campaign'} (catalogue {result.catalogue})")
    print(f"figure:   {figure}")
    print("stages implemented so far: synth. Identification, clustering, forecasting and the report "
          "are not part of this build yet (see the README).")
    return 0


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vivbench", description="Time-varying SINDy testbed for bridge VIV.")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    default_workers = min(2, os.cpu_count() or 1)

    s = sub.add_parser("synth", help="generate a synthetic campaign (event files + catalogue.csv)")
    s.add_argument("--events", type=int, default=31, help="number of events (default 31)")
    s.add_argument("--seed", type=int, default=0, help="campaign seed (default 0)")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--duration", type=_duration, default=(1200.0, 3600.0),
                   help="event duration in minutes: N or MIN-MAX (default 20-60)")
    s.add_argument("--config", help="generator configuration (TOML); defaults otherwise")
    s.add_argument("--workers", type=int, default=default_workers, help="worker processes (files do not depend on it)")
    s.set_defaults(func=_cmd_synth)

    s = sub.add_parser("plot-event", help="overview figure of one event file")
    s.add_argument("event", help="event file (.nc)")
    s.add_argument("--out", required=True, help="output PNG")
    s.add_argument("--section", default="S2", choices=("S1", "S2", "S3"))
    s.set_defaults(func=_cmd_plot_event)

    s = sub.add_parser("demo", help="run the implemented chain on the default synthetic campaign")
    s.add_argument("--out", default="demo", help="output directory (default ./demo)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--workers", type=int, default=default_workers)
    s.set_defaults(func=_cmd_demo)
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from vivbench.io import EventFormatError

    try:
        return args.func(args)
    except (EventFormatError, ValueError, OSError) as exc:
        message = " ".join(str(exc).split())
        print(f"vivbench {args.command}: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"vivbench {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
