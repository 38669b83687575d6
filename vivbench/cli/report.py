"""``vivbench report``: the Markdown report of a campaign with the paper's figures."""

from __future__ import annotations

from pathlib import Path

from vivbench.core.steps import EXTRA_STEPS


def run(args) -> int:
    from vivbench.report import write_report

    extra = {step: getattr(args, step) for step in EXTRA_STEPS}
    path = write_report(args.name, args.campaign, args.results, out_root=args.out_root, extra_dirs=extra,
                        events=args.events, max_rows=args.max_rows, baseline=args.baseline,
                        twin=args.twin)
    not_run = [step for step, d in extra.items() if d is None or not Path(d).is_dir()]
    print(f"wrote {path}" + (f" (not run: {', '.join(not_run)})" if not_run else ""))
    return 0


def register(sub) -> None:
    s = sub.add_parser("report", help="write reports/<name>/report.md with the paper's figures and recovery tables")
    s.add_argument("--campaign", required=True, help="campaign directory (<event_id>.nc, catalogue.csv)")
    s.add_argument("--results", required=True, help="identification results directory (<event_id>.identify.nc)")
    s.add_argument("--name", required=True, help="report name: the report goes to OUT_ROOT/NAME/report.md")
    s.add_argument("--out-root", default="reports", help="parent directory of the report (default ./reports)")
    for step in EXTRA_STEPS:
        s.add_argument(f"--{step}", default=None, metavar="DIR",
                       help=f"output directory of `vivbench {step}` (embedded; listed as not run when absent)")
    s.add_argument("--baseline", default=None, metavar="DIR",
                   help="a second run of the chain shown side by side with this one, normally the in-library "
                        "campaign (truth inside the model class: the inverse crime) of `vivbench demo --mode "
                        "in_library --out DIR` with the same seed: DIR holds campaign/ and identify/, and "
                        "optionally cluster/, forecast/, validate/ (default: none; the report is then unchanged)")
    s.add_argument("--twin", default=None, metavar="DIR",
                   help="output directory of `vivbench twin` on this campaign: adds the section \"How far to trust "
                        "this\" with the recovery expected on this bridge (default: none; the report is then unchanged)")
    s.add_argument("--events", nargs="+", default=None, metavar="EVENT_ID",
                   help="events featured in the figures (default: the first three with results)")
    s.add_argument("--max-rows", type=int, default=30, help="rows shown of each embedded CSV (default 30)")
    s.set_defaults(func=run)
