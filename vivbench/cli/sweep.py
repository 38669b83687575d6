"""``vivbench sweep``: Monte-Carlo recovery sweep over noise, turbulence and bridge parameters."""

from __future__ import annotations

import sys
from pathlib import Path

from vivbench.cli.common import DEFAULT_WORKERS, progress, record_command


def run(args) -> int:
    from vivbench.validate import load_sweep_config, run_sweep

    config = load_sweep_config(args.grid)
    bar = progress(config.n_tasks, "sweep", unit="campaign")

    def advance(done: int, _total: int) -> None:
        bar.update(done - bar.n)

    try:
        result = run_sweep(config, args.out, workers=args.workers, scheduler=args.scheduler,
                           keep_files=args.keep_files, progress=advance)
    except KeyboardInterrupt:
        bar.close()
        print(f"vivbench sweep: interrupted; the finished campaigns are saved in {Path(args.out) / 'sweep.jsonl'}: "
              "run the same command again to resume", file=sys.stderr)
        return 130
    finally:
        bar.close()
    record_command(args.out, args)
    for task_id, message in sorted(result.failures.items()):
        print(f"vivbench sweep: task {task_id}: {message}", file=sys.stderr)
    notes = []
    if result.resumed:
        notes.append(f"{len(result.resumed)} resumed from {result.table.parent / 'sweep.jsonl'}")
    if result.repaired_lines:
        notes.append(f"{result.repaired_lines} broken journal line(s) dropped")
    extra = f" ({'; '.join(notes)})" if notes else ""
    print(f"sweep: {result.n_tasks} campaigns, {len(result.computed)} computed, {len(result.failures)} failed{extra}")
    print(f"table {result.table}; summary {result.summary}; figures {', '.join(str(f) for f in result.figures)}")
    return 1 if result.failures else 0


def register(sub) -> None:
    s = sub.add_parser("sweep", help="Monte-Carlo recovery sweep (writes sweep.csv, figures, summary.json); resumable")
    s.add_argument("--grid", required=True, help="sweep configuration (TOML; see examples/sweep_small.toml)")
    s.add_argument("--out", required=True,
                   help="output directory; rerunning with the same --grid and --out resumes a stopped sweep")
    s.add_argument("--workers", type=int, default=DEFAULT_WORKERS,
                   help="local worker processes (results do not depend on it)")
    s.add_argument("--scheduler", default=None,
                   help="dask: local:N starts a local cluster of N processes; or a scheduler address tcp://HOST:PORT")
    s.add_argument("--keep-files", action="store_true",
                   help="keep every campaign and its identification results under OUT/files/ (default: deleted)")
    s.set_defaults(func=run)
