"""The pysindy variants (STLSQ, ensembles, SBR, the weak form) beside varying, pooled and binned, on evaluation draws.

Run::

    .venv/bin/python benchmarks/run_study.py pysindy_variants --draws 30-34
    .venv/bin/python benchmarks/run_study.py pysindy_variants --draws 30 --max-events 1 --max-duration 300

The factories of :mod:`vivbench.models.pysindy_variants` (``stlsq``, ``ensemble``,
``ensemble_median``, ``sbr``, ``weak``), each with its defaults (SBR: 300 warm-up and 300
kept NUTS samples on at most 2000 samples of the records, 100 posterior draws for the
verdict), are scored beside the built-in ``varying`` and ``pooled`` campaign models and
the ``binned`` floor on draws of the generator family's evaluation split, by the study
machinery of ``vivbench study`` (:func:`vivbench.validate.run_study`: every draw's
campaign generated, identified by the chain, every method fitted on the identified
records and scored against the truth on the identification's windows). Evaluation draws
are only reported, never used to choose anything. The default draws are the first ones
from draw 30, where the evaluation study of ``vivbench study`` starts (30, 31, ... in
order, none left out); how many is set by the cost: the ensembles' 20 bags and SBR's
NUTS chain grow with the polynomial library, C(2S + 3, 3) terms in the S sections'
amplitudes and winds (286 for five sections), and the first five draws are what one
worker computes in about an hour on a shared two-core machine.

Per draw and method: the energy-weighted dA/dt error on the true (A, U)
(``rhs_error_true_AU_energy``), the coverage (share of window-equations flagged), the
number flagged, the share of them whose regime is right (``flagged_right_share``), the
fit time (s) and, when the method could not be fitted or scored on that draw, the reason
(its one-line error; the other methods are scored). Per method, over the draws: the
median, 90th percentile and worst of the error, the median coverage and share of flags
right, whether the verdict keeps its promise (at least 95 % of the flags right on every
draw with at least 20 flags), on how many draws its error is below binned's and below
varying's, and the median fit time. The sentences under "What the figures show" are
generated from these figures.

Finished draws are journalled under ``--out``: a run stopped part-way resumes, and the
page then gives the summed task time of every draw beside the run's own wall time.
``run_study.py`` writes the figures to ``docs/results/studies/pysindy_variants.md``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from vivbench.validate.journal import load as journal_load  # noqa: E402
from vivbench.validate.study import StudyConfig, parse_draws, run_study  # noqa: E402
from vivbench.validate.study_report import PROMISE_MIN_FLAGS, PROMISE_SHARE  # noqa: E402

OUT = Path(__file__).resolve().parent / "out" / "pysindy_variants"
VARIANTS = "vivbench.models.pysindy_variants:"
#: The methods, built-in names first, then the variants' factories (short names on the page).
METHODS = ("varying", "pooled", "binned", *(VARIANTS + f for f in ("stlsq", "ensemble", "ensemble_median", "sbr",
                                                                   "weak")))
ERROR = "rhs_error_true_AU_energy"


def short(method: str) -> str:
    """A method's name on the page: the factory's name for a variant."""
    return method.removeprefix(VARIANTS)


def _num(x) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def draw_rows(config: StudyConfig, journal: dict) -> list[dict]:
    """One row per draw and method, from the study's journal (fit times are kept there only)."""
    rows = []
    for d in config.draws:
        rec = journal.get(d)
        if rec is None:
            continue
        for m in config.methods:
            s = rec["methods"].get(m, {})
            flagged = _num(s.get("n_flagged"))
            rows.append({"draw": d, "n_events": rec["n_events"], "yaw_effect": rec["labels"].get("yaw_effect"),
                         "method": short(m), ERROR: _num(s.get(ERROR)), "coverage": _num(s.get("coverage")),
                         "n_flagged": int(flagged) if math.isfinite(flagged) else None,
                         "flagged_right_share": _num(s.get("flagged_right_share")),
                         "fit_time_s": round(_num(s.get("fit_time_s")), 1), "reason": s.get("error", "")})
    return rows


def method_rows(config: StudyConfig, summary: dict, rows: list[dict]) -> list[dict]:
    """One row per method: its scores over the draws (from the study's summary) and its fit time."""
    out = []
    for m in config.methods:
        block = summary["methods"][m]["all"]
        err, promise = block["scores"][ERROR], block["promise"]
        mine = [r for r in rows if r["method"] == short(m)]
        times = [r["fit_time_s"] for r in mine if math.isfinite(r["fit_time_s"])]
        vs = {ref: summary["versus"].get(f"{m} vs {ref}") for ref in ("binned", "varying") if ref != m}
        out.append({
            "method": short(m), "draws_scored": err["n"], "draws_refused": block["method_errors"],
            "error_median": err["median"], "error_p90": err["p90"], "error_worst": err["worst"],
            "worst_draw": err["worst_draw"], "coverage_median": block["scores"]["coverage"]["median"],
            "flags": int(sum(r["n_flagged"] or 0 for r in mine)),
            "flagged_right_median": block["scores"]["flagged_right_share"]["median"],
            "promise_draws": promise["draws_with_enough_flags"], "promise_kept": promise["draws_kept"],
            "below_binned": _versus_text(vs.get("binned")), "below_varying": _versus_text(vs.get("varying")),
            "fit_time_median_s": float(np.median(times)) if times else None})
    ranks = {m["method"]: i + 1 for i, m in enumerate(sorted(
        (m for m in out if m["draws_scored"]), key=lambda m: (m["error_median"], m["error_p90"])))}
    return [{"rank": ranks.get(m["method"]), **m} for m in out]


def _versus_text(v: dict | None) -> str:
    return "" if v is None else f"{v['lower']} of {v['draws']}"


def findings(config: StudyConfig, methods: list[dict], rows: list[dict], task_seconds: float,
             resumed: int = 0) -> list[str]:
    """What the figures show, in sentences generated from them (``resumed``: draws read back from the journal)."""
    by = {r["method"]: r for r in methods}
    draws = sorted({r["draw"] for r in rows})
    events = sum({r["draw"]: r["n_events"] for r in rows}.values())
    text = f"Draws: evaluation draws {_ranges(draws)} ({len(draws)} campaigns, {events} events"
    text += ", capped: not the family's campaigns)" if config.capped else ")"
    if draws and draws[0] == 30 and draws == list(range(30, 30 + len(draws))):
        text += (", the first ones from draw 30 in order, none left out; as many as one worker computes in about an hour "
                 "on a shared two-core machine")
    text += f". The draws' tasks took {task_seconds / 60:.0f} min of one worker in all"
    if resumed:
        text += (f"; {resumed} of the draws were computed by an earlier run with the same configuration and read "
                 "back from the study's journal, so the run's own wall time above is not the study's cost")
    out = [text + "."]
    ranked = sorted((m for m in methods if m["draws_scored"]), key=lambda m: (m["error_median"], m["error_p90"]))
    if ranked:
        out.append("Ranked by the median over the draws of the energy-weighted dA/dt error on the true (A, U), lowest "
                   "first: " + ", ".join(f"{m['method']} {m['error_median']:.3g}" for m in ranked) + ". Fit times "
                   "are wall times on a two-core machine shared with other work: compare them with each other.")
    ref = {k: by[k]["error_median"] for k in ("binned", "varying") if k in by}
    for m in methods:
        name = m["method"]
        if m["draws_scored"] == 0:
            reasons = sorted({r["reason"] for r in rows if r["method"] == name and r["reason"]})
            out.append(f"{name}: refused on every draw ({'; '.join(reasons) or 'no score'}).")
            continue
        text = (f"{name}: energy-weighted dA/dt error median {m['error_median']:.3g}, 90th percentile "
                f"{m['error_p90']:.3g}, worst {m['error_worst']:.3g} (draw {m['worst_draw']})")
        if "binned" in ref and name != "binned":
            text += f"; below binned's on {m['below_binned']} draws"
        if "varying" in ref and name != "varying":
            text += f", below varying's on {m['below_varying']}"
        text += f"; median fit {m['fit_time_median_s']:.3g} s."
        if m["flags"]:
            if m["promise_draws"]:
                kept = m["promise_kept"] == m["promise_draws"]
                text += (f" Its verdict flagged {m['flags']} window-equations in all; on the {m['promise_draws']} "
                         f"draws with at least {PROMISE_MIN_FLAGS} flags, at least {PROMISE_SHARE:.0%} of the flags "
                         f"were right on {m['promise_kept']}: the promise is {'kept' if kept else 'broken'}"
                         f" (median share of flags right {m['flagged_right_median']:.3g}).")
            else:
                text += (f" Its verdict flagged {m['flags']} window-equations, on no draw {PROMISE_MIN_FLAGS} or "
                         "more: too few to test the promise.")
        elif name not in ("binned", "stlsq", "weak"):
            text += " Its verdict flagged nothing."
        refused = sorted({(r["draw"], r["reason"]) for r in rows if r["method"] == name and r["reason"]})
        if refused:
            text += " Refused on draw " + "; ".join(f"{d} ({why})" for d, why in refused) + "."
        out.append(text)
    return out


def _ranges(draws: list[int]) -> str:
    if len(draws) > 2 and draws == list(range(draws[0], draws[-1] + 1)):
        return f"{draws[0]}-{draws[-1]}"
    return ", ".join(str(d) for d in draws) or "none"


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--draws", default="30-34", help="evaluation draws: N, N-M or a comma-separated list (default 30-34)")
    p.add_argument("--methods", default=",".join(METHODS),
                   help="comma-separated method specs (default: varying, pooled, binned and the five variants)")
    p.add_argument("--max-events", type=int, default=None, help="cap on each campaign's events (quick checks)")
    p.add_argument("--max-duration", type=float, default=None, help="cap on each event's duration, s (quick checks)")
    p.add_argument("--workers", type=int, default=1, help="local worker processes (default 1)")
    p.add_argument("--out", type=Path, default=OUT, help="the study's directory (journal, study.csv, study.md)")
    args = p.parse_args(argv)
    config = StudyConfig(split="evaluation", draws=parse_draws(args.draws),
                         methods=tuple(m.strip() for m in args.methods.split(",") if m.strip()),
                         max_events=args.max_events, max_duration=args.max_duration)
    t0 = time.perf_counter()
    result = run_study(config, args.out, workers=args.workers,
                       progress=lambda n, total: print(f"pysindy_variants: {n}/{total} draws after "
                                                       f"{time.perf_counter() - t0:.0f} s", file=sys.stderr,
                                                       flush=True))
    journal, _ = journal_load(args.out / "study.jsonl", n_tasks=2**31, columns=("task_id", "draw", "methods"))
    summary = json.loads(result.summary.read_text(encoding="utf-8"))
    rows = draw_rows(config, journal)
    methods = method_rows(config, summary, rows)
    task_seconds = sum(result.seconds.values())
    return {"findings": findings(config, methods, rows, task_seconds, len(result.resumed)),
            "split": "evaluation", "draws": _ranges(list(config.draws)), "capped": config.capped,
            "max_events": args.max_events, "max_duration_s": args.max_duration,
            "draws_failed": ", ".join(f"{d}: {why}" for d, why in sorted(result.failures.items())) or "none",
            "draws_computed_by_this_run": len(result.computed), "draws_resumed_from_journal": len(result.resumed),
            "task_seconds_total": round(task_seconds, 1),
            "methods": methods, "per_draw": rows}


if __name__ == "__main__":
    main()
