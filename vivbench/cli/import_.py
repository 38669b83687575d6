"""``vivbench import``: field data (CSV or MAT files described by a TOML mapping) to an event file."""

from __future__ import annotations


def run(args) -> int:
    from vivbench.io import NOMINAL_RATES
    from vivbench.io.fieldimport import import_event

    tree = import_event(args.mapping, args.out)
    attrs = tree.attrs
    t = tree["wind"]["time"].values
    resampled = ", ".join(f"{g} {attrs[f'import_rate_{g}_hz']:.4g} -> {NOMINAL_RATES[g]:g} Hz" for g in ("wind", "accel")
                          if attrs.get(f"import_resampled_{g}"))
    repairs = ", ".join(f"{k[len('quality_'):]} {v}" for k, v in attrs.items() if k.startswith("quality_") and v)
    print(f"wrote {args.out}: event {attrs['event_id']}, {tree['wind'].sizes['section']} sections, "
          f"{t[-1] - t[0]:.0f} s" + (f"; resampled: {resampled}" if resampled else "")
          + (f"; repairs: {repairs}" if repairs else ""))
    return 0


def register(sub) -> None:
    s = sub.add_parser("import", help="import field data (CSV or MATLAB files named in a TOML mapping) as an event file")
    s.add_argument("mapping", help="mapping file (TOML): files, columns, units, time format; see docs/field_import.md")
    s.add_argument("--out", required=True, help="event file to write (EVENT.nc)")
    s.set_defaults(func=run)
