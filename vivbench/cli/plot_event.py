"""``vivbench plot-event``: overview figure of one event file."""

from __future__ import annotations


def run(args) -> int:
    from vivbench.io.event import read_event
    from vivbench.report import event_figure

    out = event_figure(read_event(args.event), args.out, section=args.section)
    print(f"wrote {out}")
    return 0


def register(sub) -> None:
    s = sub.add_parser("plot-event", help="overview figure of one event file")
    s.add_argument("event", help="event file (.nc)")
    s.add_argument("--out", required=True, help="output PNG")
    s.add_argument("--section", default=None,
                   help="section shown, e.g. S1 (default: the middle one, S2 of three)")
    s.set_defaults(func=run)
