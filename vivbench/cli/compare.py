"""``vivbench compare``: the identification chain scored over a grid of method variants."""

from __future__ import annotations

import sys

from vivbench.cli.common import DEFAULT_WORKERS, progress, record_command


def run(args) -> int:
    from vivbench.validate import load_compare_config, plan, run_comparison

    config = load_compare_config(args.grid)
    n_campaigns, n_cells = plan(config)
    bar = progress(n_campaigns + n_cells, "compare", unit="task")
    try:
        result = run_comparison(config, args.out, workers=args.workers, scheduler=args.scheduler,
                                progress=lambda _kind: bar.update())
    finally:
        bar.close()
    record_command(args.out, args)
    for what, message in result.failures.items():
        print(f"vivbench compare: {what}: {message}", file=sys.stderr)
    print(f"wrote {result.table} ({len(result.rows)} cells), {len(result.figures)} figures and {result.summary}")
    return 1 if result.failures else 0


def register(sub) -> None:
    s = sub.add_parser("compare", help="compare method variants on synthetic campaigns (writes compare.csv, plots)")
    s.add_argument("--grid", required=True, help="comparison grid (TOML): design, [campaign], [base], [grid]")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--workers", type=int, default=DEFAULT_WORKERS,
                   help="local worker processes (the table does not depend on it)")
    s.add_argument("--scheduler", default=None,
                   help="dask scheduler: local:N (a local cluster of N processes) or an address tcp://host:port")
    s.set_defaults(func=run)
