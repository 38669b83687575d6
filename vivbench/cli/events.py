"""``vivbench events``: VIV events found in continuous field records, one event file each and a catalogue."""

from __future__ import annotations


def run(args) -> int:
    from vivbench.cli.common import progress
    from vivbench.preprocess.event_detection import EventDetectionConfig
    from vivbench.preprocess.event_log import find_events

    config = EventDetectionConfig(
        threshold_factor=args.threshold_factor, threshold_m=args.threshold, min_duration_s=args.min_duration,
        merge_gap_s=args.merge_gap, margin_s=args.margin, frequency_hz=args.frequency,
        band_hz=tuple(args.band), half_width=args.half_width, smoothing_s=args.smoothing,
    )
    with progress(None, "events", unit="step") as bar:
        def step(what: str) -> None:
            bar.set_postfix_str(what)
            bar.update()

        result = find_events(args.mapping, args.out, config, progress=step)
    d = result.detection
    floors = ", ".join(f"{x:.3g}" for x in d.noise_floor_m)
    thresholds = ", ".join(f"{x:.3g}" for x in d.threshold_m)
    print(f"{args.mapping}: mode {d.frequency_hz:.4g} Hz, noise floor {floors} m, threshold {thresholds} m "
          f"(per section); {len(result.files)} events")
    for row in result.rows:
        print(f"  {row['event_id']}: {row['start']} to {row['end']} ({float(row['duration_s']):.0f} s), "
              f"peak {row['peak_amplitude_m']} m at {row['peak_section']}, wind {row['mean_wind_m_s']} m/s")
    print(f"wrote {len(result.files)} event files and {result.catalogue}")
    return 0


def register(sub) -> None:
    s = sub.add_parser("events", help="find VIV events in continuous field records (a TOML mapping) and write "
                                      "one event file each plus catalogue.csv")
    s.add_argument("mapping", help="mapping file (TOML) of the log's files, as for vivbench import; its event_id "
                                   "prefixes the events' ids; see docs/event_detection.md")
    s.add_argument("--out", required=True, help="directory for <event_id>.nc and catalogue.csv")
    s.add_argument("--threshold-factor", type=float, default=12.0,
                   help="threshold as a multiple of each section's noise floor (median amplitude); default 12")
    s.add_argument("--threshold", type=float, default=None, metavar="M",
                   help="absolute amplitude threshold in m (replaces --threshold-factor)")
    s.add_argument("--min-duration", type=float, default=60.0, metavar="S", help="shortest event, s; default 60")
    s.add_argument("--merge-gap", type=float, default=300.0, metavar="S",
                   help="events closer than this are one, s; default 300")
    s.add_argument("--margin", type=float, default=300.0, metavar="S",
                   help="record kept before and after each event, s; default 300")
    s.add_argument("--frequency", type=float, default=None, metavar="HZ",
                   help="the mode's frequency, Hz; default: the acceleration spectrum's peak in --band")
    s.add_argument("--band", type=float, nargs=2, default=(0.05, 2.0), metavar=("LO", "HI"),
                   help="search band of the spectral peak, Hz; default 0.05 2")
    s.add_argument("--half-width", type=float, default=0.1,
                   help="half-width of the band around the mode, fraction of its frequency; default 0.1")
    s.add_argument("--smoothing", type=float, default=20.0, metavar="S",
                   help="moving average of the amplitude envelope, s; default 20")
    s.set_defaults(func=run)
