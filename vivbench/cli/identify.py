"""``vivbench identify``: time-varying SINDy on event files."""

from __future__ import annotations

import sys

from vivbench.cli.common import DEFAULT_WORKERS, event_paths, progress


def run(args) -> int:
    from vivbench.preprocess.derivative import Derivative
    from vivbench.analysis.identify import IdentifyConfig, identify_files
    from vivbench.preprocess.config import PreprocessConfig

    deriv_opts = {}
    if args.tv_time_scale is not None:
        deriv_opts["time_scale"] = args.tv_time_scale
    if args.tv_huber is not None:
        deriv_opts["huber"] = args.tv_huber
    if args.tv_noise_scale is not None:
        deriv_opts["noise_scale"] = args.tv_noise_scale
    config = IdentifyConfig(
        preprocess=PreprocessConfig(modal_frequency_hz=args.mode_frequency, grid_step_s=args.grid_step),
        derivative=Derivative.for_envelope(args.derivative, **deriv_opts),
        window=args.window, step=args.step, alpha=args.alpha, scaling=args.scaling, tau=args.tau,
        fit_tolerance=args.fit_tolerance, spike_mad=args.spike_mad or None, min_snr=args.min_snr or None,
        optimizer=args.optimizer, seed=args.seed,
    )
    paths = event_paths(args.inputs)
    bar = progress(len(paths), "identify")
    try:
        written, failures = identify_files(paths, args.out, config, workers=args.workers, progress=lambda _p: bar.update())
    finally:
        bar.close()
    for message in failures.values():
        print(f"vivbench identify: {message}", file=sys.stderr)
    print(f"wrote {len(written)} result files to {args.out}")
    return 1 if failures else 0


def register(sub) -> None:
    s = sub.add_parser("identify", help="time-varying SINDy on event files (writes <event_id>.identify.nc)")
    s.add_argument("inputs", nargs="+", help="campaign directories and/or event files")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--window", type=float, default=50.0, help="window width, s (default 50)")
    s.add_argument("--step", type=float, default=25.0, help="window step, s (default 25)")
    s.add_argument("--derivative", default="tv", choices=("tv", "savgol", "spline", "finite_difference"),
                   help="dA/dt method (default tv: total-variation regularised)")
    s.add_argument("--tv-time-scale", type=float, default=None, help="time scale of the automatic TV weight, s (default 20)")
    s.add_argument("--tv-huber", type=float, default=None, help="Huber threshold of the TV derivative (default 10; 0: exact TV)")
    s.add_argument("--tv-noise-scale", type=float, default=None,
                   help="time scale at which the TV weight's noise level is measured, s (default 10, for the "
                        "envelope's band-limited noise; 0: white-noise estimate)")
    s.add_argument("--alpha", type=float, default=0.05, help="STLSQ ridge parameter (default 0.05)")
    s.add_argument("--scaling", default="scaled", choices=("scaled", "normalized", "raw"), help="library basis")
    s.add_argument("--optimizer", default="stlsq", choices=("stlsq", "sr3", "ensemble"),
                   help="sparse regression per window (default stlsq: the fast engine; sr3, ensemble: pysindy)")
    s.add_argument("--seed", type=int, default=0, help="seed of the ensemble optimiser's bootstrap samples")
    s.add_argument("--tau", type=float, default=0.2, help="regime threshold (docs/concepts.md (regimes))")
    s.add_argument("--fit-tolerance", type=float, default=0.1,
                   help="relative RMS residual within which a competing model fits equally well (default 0.1)")
    s.add_argument("--spike-mad", type=float, default=8.0,
                   help="spike rule: robust standard deviations from the local median (default 8; 0: off)")
    s.add_argument("--min-snr", type=float, default=3.0,
                   help="identifiable only if the window's mean amplitude is at least this many times the "
                        "accelerometer noise floor (default 3; 0: off)")
    s.add_argument("--mode-frequency", type=float, default=None, help="modal frequency, Hz (default: from the spectrum)")
    s.add_argument("--grid-step", type=float, default=0.25, help="common time grid step, s (default 0.25)")
    s.add_argument("--workers", type=int, default=DEFAULT_WORKERS, help="worker processes (results do not depend on it)")
    s.set_defaults(func=run)
