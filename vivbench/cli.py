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


def _event_paths(inputs: list[str]) -> list[Path]:
    from vivbench.io import list_events

    paths: list[Path] = []
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            found = list_events(p)
            if not found:
                raise ValueError(f"{p}: no event files (<event_id>.nc) in this directory")
            paths.extend(found)
        else:
            paths.append(p)
    return paths


def _cmd_identify(args) -> int:
    from vivbench.identify import Derivative, IdentifyConfig, PreprocessConfig, identify_files

    deriv_opts = {}
    if args.tv_time_scale is not None:
        deriv_opts["time_scale"] = args.tv_time_scale
    config = IdentifyConfig(
        preprocess=PreprocessConfig(modal_frequency_hz=args.mode_frequency, grid_step_s=args.grid_step),
        derivative=Derivative(method=args.derivative, **deriv_opts),
        window=args.window, step=args.step, alpha=args.alpha, scaling=args.scaling, tau=args.tau,
        fit_tolerance=args.fit_tolerance,
    )
    paths = _event_paths(args.inputs)
    bar = _progress(len(paths), "identify")
    try:
        written, failures = identify_files(paths, args.out, config, workers=args.workers, progress=lambda _p: bar.update())
    finally:
        bar.close()
    for message in failures.values():
        print(f"vivbench identify: {message}", file=sys.stderr)
    print(f"wrote {len(written)} result files to {args.out}")
    return 1 if failures else 0


def _cmd_plot_event(args) -> int:
    from vivbench.io import read_event
    from vivbench.report import event_figure

    tree = read_event(args.event)
    out = event_figure(tree, args.out, section=args.section)
    print(f"wrote {out}")
    return 0


def _cmd_demo(args) -> int:
    from vivbench.identify import identify_files
    from vivbench.io import read_event
    from vivbench.report import event_figure
    from vivbench.synth import CampaignConfig, generate_campaign
    from vivbench.validate import campaign_recovery

    out = Path(args.out)
    campaign = CampaignConfig(seed=args.seed, n_events=args.events, duration=args.duration)
    bar = _progress(campaign.n_events, "synth")
    try:
        result = generate_campaign(campaign, out / "campaign", workers=args.workers, progress=lambda _id: bar.update())
    finally:
        bar.close()
    failed = dict(result.failures)
    bar = _progress(len(result.files), "identify")
    try:
        written, id_failures = identify_files(result.files, out / "identify", workers=args.workers,
                                              progress=lambda _p: bar.update())
    finally:
        bar.close()
    failed.update(id_failures)
    for key, message in sorted(failed.items()):
        print(f"vivbench demo: {message if message.startswith(str(key)) else f'{key}: {message}'}", file=sys.stderr)
    figure = event_figure(read_event(result.files[0]), out / "event_E001.png")
    done = {Path(p).name.replace(".identify.nc", ".nc") for p in written}
    scores = campaign_recovery([f for f in result.files if f.name in done], written)
    print(f"campaign: {len(result.files)} events in {out / 'campaign'} (catalogue {result.catalogue})")
    print(f"identify: {len(written)} result files in {out / 'identify'}")
    print(f"figure:   {figure}")
    print(f"recovery: {scores['n']} window-equations; regime coverage (identifiable) {scores['coverage']:.3f}, "
          f"regime accuracy {scores['accuracy_all']:.3f} overall and {scores['accuracy_identifiable']:.3f} on identifiable ones; "
          f"median relative error of dA/dt {scores['rhs_median_rel_error_active']:.3f} on windows with dynamics")
    print("not in this build yet: clustering, forecasting, refit, validation tables and the report (see the README).")
    return 1 if failed else 0


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

    s = sub.add_parser("identify", help="time-varying SINDy on event files (writes <event_id>.identify.nc)")
    s.add_argument("inputs", nargs="+", help="campaign directories and/or event files")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--window", type=float, default=50.0, help="window width, s (default 50)")
    s.add_argument("--step", type=float, default=25.0, help="window step, s (default 25)")
    s.add_argument("--derivative", default="tv", choices=("tv", "savgol", "spline", "finite_difference"),
                   help="dA/dt method (default tv: total-variation regularised)")
    s.add_argument("--tv-time-scale", type=float, default=None, help="time scale of the automatic TV weight, s")
    s.add_argument("--alpha", type=float, default=0.05, help="STLSQ ridge parameter (default 0.05)")
    s.add_argument("--scaling", default="scaled", choices=("scaled", "normalized", "raw"), help="library basis")
    s.add_argument("--tau", type=float, default=0.2, help="regime threshold (DESIGN 2.5)")
    s.add_argument("--fit-tolerance", type=float, default=0.1,
                   help="relative RMS residual within which a competing model fits equally well (default 0.1)")
    s.add_argument("--mode-frequency", type=float, default=None, help="modal frequency, Hz (default: from the spectrum)")
    s.add_argument("--grid-step", type=float, default=0.25, help="common time grid step, s (default 0.25)")
    s.add_argument("--workers", type=int, default=default_workers, help="worker processes (results do not depend on it)")
    s.set_defaults(func=_cmd_identify)

    s = sub.add_parser("plot-event", help="overview figure of one event file")
    s.add_argument("event", help="event file (.nc)")
    s.add_argument("--out", required=True, help="output PNG")
    s.add_argument("--section", default="S2", choices=("S1", "S2", "S3"))
    s.set_defaults(func=_cmd_plot_event)

    s = sub.add_parser("demo", help="generate the default campaign, identify it and score the recovery")
    s.add_argument("--out", default="demo", help="output directory (default ./demo)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--events", type=int, default=31, help="number of events (default 31)")
    s.add_argument("--duration", type=_duration, default=(1200.0, 3600.0),
                   help="event duration in minutes: N or MIN-MAX (default 20-60)")
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
