"""The command-line options shared by the studies over draws of the generator family."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def family_parser(description: str, *, draws_help: str = "N, N-M or a comma-separated list",
                  max_events: int | None = None, max_duration: float | None = None) -> argparse.ArgumentParser:
    """A parser with ``--split``, ``--draws``, ``--out`` (the resumable study directory), the campaigns'
    caps ``--max-events`` and ``--max-duration`` (minutes; defaults as given) and ``--workers``."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--split", required=True, choices=("development", "evaluation"))
    parser.add_argument("--draws", required=True, help=draws_help)
    parser.add_argument("--out", required=True, type=Path, help="study directory (resumable)")
    parser.add_argument("--max-events", type=int, default=max_events)
    parser.add_argument("--max-duration", type=float, default=max_duration, metavar="MINUTES")
    parser.add_argument("--workers", type=int, default=1)
    return parser


def root_on_path() -> None:
    """Put the repository's root on ``sys.path``, so that the package ``benchmarks`` (a study's methods or task
    functions, named ``benchmarks.<study>:...``) imports here and in forked worker processes (``run_study.py``
    does it for every study)."""
    root = str(Path(__file__).resolve().parent.parent)
    if root not in sys.path:
        sys.path.insert(0, root)


def run_draws(study: str, function: str, args: argparse.Namespace, **extra) -> tuple[list[int], list[dict], list[dict]]:
    """Run ``benchmarks.<study>.<function>(task)`` for every draw of ``args`` (a :func:`family_parser` namespace)
    on ``args.workers`` local processes.

    Each task is a dict with ``split``, ``draw``, ``out`` (the study directory), ``max_events``,
    ``max_duration_s`` and the study's own ``extra`` keys. Returns the draws, the rows of the draws that ran (sorted by draw) and the failed
    draws with the first line of their error.
    """
    import importlib

    from vivbench.core.parallel import run_tasks
    from vivbench.validate.study import parse_draws

    # The tasks' function must be importable by the worker processes: a module of the package ``benchmarks``.
    root_on_path()
    task_function = getattr(importlib.import_module(f"benchmarks.{study}"), function)
    draws = list(parse_draws(args.draws))
    tasks = [{"split": args.split, "draw": d, "out": str(args.out.resolve()), "max_events": args.max_events,
              "max_duration_s": args.max_duration * 60.0, **extra} for d in draws]
    rows, failed = [], []
    for outcome in run_tasks(task_function, tasks, workers=args.workers):
        if outcome.error is not None:
            failed.append({"draw": draws[outcome.index], "error": str(outcome.error).splitlines()[0]})
        else:
            rows.append(outcome.value)
    rows.sort(key=lambda r: r["draw"])
    return draws, rows, failed


def draw_dir(task: dict) -> Path:
    """The draw's directory of the study, ``<out>/dNNN``: its campaign, identification and ``row.json``."""
    return Path(task["out"]) / f"d{task['draw']:03d}"


def stored_row(task: dict) -> dict | None:
    """The draw's scores from an earlier run of the study (its ``row.json``), or None."""
    import json

    done = draw_dir(task) / "row.json"
    return json.loads(done.read_text(encoding="utf-8")) if done.exists() else None


def store_row(task: dict, row: dict) -> dict:
    """Write the draw's scores (``row.json``, atomically) and return them."""
    import json

    from vivbench.io.netcdf import atomic_path

    root = draw_dir(task)
    root.mkdir(parents=True, exist_ok=True)
    with atomic_path(root / "row.json") as tmp:
        Path(tmp).write_text(json.dumps(row, default=float), encoding="utf-8")
    return row


def capped_draw(task: dict) -> tuple[list, list, list]:
    """The draw's campaign generated with the task's caps and identified (in :func:`draw_dir`, unless it already
    holds them): the records, truths and windows to score a model on
    (:func:`vivbench.validate.methods.scoring_inputs`)."""
    from vivbench.analysis.identify import IdentifyConfig, identify_files
    from vivbench.synth.family import generate_family_campaign
    from vivbench.validate.methods import scoring_inputs

    root = draw_dir(task)
    if not _identified(root):
        made, _ = generate_family_campaign(task["split"], task["draw"], root / "campaign", max_events=task["max_events"],
                                           max_duration=task["max_duration_s"])
        identify_files(made.files, root / "identify", IdentifyConfig(), workers=1)
    return scoring_inputs(*draw_files(task))


def _identified(root: Path) -> bool:
    """Whether a draw directory holds a campaign (its catalogue) with every event identified: a directory copied
    from another study of the same caps is read, not generated and identified again."""
    campaign = root / "campaign"
    if not (campaign / "catalogue.csv").exists():
        return False
    events = {f.stem for f in campaign.glob("*.nc")}
    done = {f.name.removesuffix(".identify.nc") for f in (root / "identify").glob("*.identify.nc")}
    return bool(events) and events <= done


def identified_campaign(root: Path, campaign) -> tuple[list, list, list]:
    """A campaign (a :class:`vivbench.synth.CampaignConfig`) generated in ``root/campaign`` and identified in
    ``root/identify`` (unless every event already is): the records, truths and windows to score a model on."""
    from vivbench.analysis.identify import IdentifyConfig, identify_files
    from vivbench.synth.campaign import generate_campaign
    from vivbench.validate.methods import scoring_inputs

    if not _identified(root):
        made = generate_campaign(campaign, root / "campaign", workers=1)
        identify_files(made.files, root / "identify", IdentifyConfig(), workers=1)
    return scoring_inputs(*campaign_files(root))


def stored_variants(task: dict, variants) -> tuple[dict | None, list[str]]:
    """The draw's stored row (or None) and the variants whose scores (``flags_<variant>``) it lacks."""
    row = stored_row(task)
    return row, [name for name in variants if row is None or f"flags_{name}" not in row]


def draw_files(task: dict) -> tuple[list, list]:
    """The event files and identification results of a draw :func:`capped_draw` made, in the same order."""
    return campaign_files(draw_dir(task))


def campaign_files(root: Path) -> tuple[list, list]:
    """The event files of ``root/campaign`` and their identification results in ``root/identify``, in the same
    order."""
    results = sorted((root / "identify").glob("*.identify.nc"))
    ids = {p.name.removesuffix(".identify.nc") for p in results}
    events = sorted(f for f in (root / "campaign").glob("*.nc") if f.stem in ids)
    return events, results


def verdict_counts(model, records, truth_regimes, windows) -> tuple[int, int, float]:
    """A fitted selection's flagged window-equations over the records, how many carry the truth's regime
    (``truth_regimes``: one (W, S) array per record) and the coverage (flagged over those where both have a regime)."""
    import math

    flagged = right = scored = 0
    for rec, tru, (s, e) in zip(records, truth_regimes, windows):
        flag = model.identifiable(rec, s, e)
        regime = model.window_regimes(rec, s, e)
        flagged += int(flag.sum())
        right += int((flag & (regime == tru)).sum())
        scored += int(((regime > 0) & (tru > 0)).sum())
    return flagged, right, flagged / scored if scored else math.nan


def promise_figures(rows: list[dict], key: str) -> dict:
    """The verdict's promise over a study's draws for one setting ``key``: each row's ``flags_<key>`` (flagged
    window-equations), ``right_<key>`` (those with the truth's regime) and ``coverage_<key>``.

    Returns ``draws_with_enough_flags`` (at least :data:`vivbench.validate.PROMISE_MIN_FLAGS`), ``promise_kept``
    (at least :data:`vivbench.validate.PROMISE_SHARE` of them right), ``worst_share_right``, ``flags``,
    ``flags_right`` and ``coverage_median`` (NaN without a coverage).
    """
    import math

    import numpy as np

    from vivbench.validate.study_report import PROMISE_MIN_FLAGS, PROMISE_SHARE

    tested = [r for r in rows if r[f"flags_{key}"] >= PROMISE_MIN_FLAGS]
    shares = [r[f"right_{key}"] / r[f"flags_{key}"] for r in tested]
    cov = np.array([r[f"coverage_{key}"] for r in rows], dtype=float)
    return {"draws_with_enough_flags": len(tested), "promise_kept": int(sum(s >= PROMISE_SHARE for s in shares)),
            "worst_share_right": min(shares, default=math.nan), "flags": int(sum(r[f"flags_{key}"] for r in rows)),
            "flags_right": int(sum(r[f"right_{key}"] for r in rows)),
            "coverage_median": float(np.nanmedian(cov)) if np.isfinite(cov).any() else math.nan}


def family_study(study: str, description: str, argv, summarise, findings, **caps) -> dict:
    """Run ``benchmarks.<study>.score_draw`` over the draws of ``argv`` (:func:`family_parser` with ``caps``) and
    return the page's figures: ``findings(summary)`` of ``summarise(rows)``, the options, failed draws and rows."""
    args = family_parser(description, **caps).parse_args(argv)
    draws, rows, failed = run_draws(study, "score_draw", args)
    summary = summarise(rows) if rows else []
    return {"findings": findings(summary), "split": args.split, "draws": draws, "max_events": args.max_events,
            "max_duration_min": args.max_duration, "failed_draws": failed, "summary": summary, "rows": rows}


def spread(values) -> dict:
    """The spread over draws of a figure (NaN and None left out): ``n``, ``median``, ``p90`` (90th percentile)
    and ``worst`` (the largest)."""
    import math

    import numpy as np

    x = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if not x.size:
        return {"n": 0, "median": math.nan, "p90": math.nan, "worst": math.nan}
    return {"n": int(x.size), "median": float(np.median(x)), "p90": float(np.percentile(x, 90)),
            "worst": float(x.max())}


def by_wind_error(rows: list[dict]) -> list[tuple[str, list[dict]]]:
    """The rows, all of them first (``"all"``), then by their draws' kind of errors in the wind (``eiv``)."""
    return [("all", rows)] + [(k, [r for r in rows if r["eiv"] == k]) for k in sorted({r["eiv"] for r in rows})]


def paired(rows: list[dict], key: str, base: str) -> dict:
    """Figure ``key`` over figure ``base`` draw by draw (where both are finite and ``base`` > 0): ``ratio_median``,
    and the draws where it is lower (``better_by_10pct``) or higher (``worse_by_10pct``) by more than 10 %."""
    import math

    import numpy as np

    q = [r[key] / r[base] for r in rows if np.isfinite(r[key]) and np.isfinite(r[base]) and r[base] > 0]
    return {"ratio_median": float(np.median(q)) if q else math.nan, "better_by_10pct": int(sum(x < 1 / 1.1 for x in q)),
            "worse_by_10pct": int(sum(x > 1.1 for x in q))}


def fit_and_score(method, records, truths, windows) -> dict:
    """Fit a study method on a draw's records and score it against the truths: ``error`` (energy-weighted
    relative dA/dt error on the truth's own (A, U)), ``curve_error`` (energy-weighted), ``flags`` (flagged
    window-equations), ``right`` (those with the truth's regime), ``coverage``, ``fit_s`` (wall time of the
    fit, s), ``chosen`` (the selection's chosen candidate, "" for other models) and ``smoothing`` (the wind
    smoothing the model was fitted with, s; NaN for models without one)."""
    import math
    import time

    from vivbench.models.protocol import model_evidence
    from vivbench.validate.methods import score_fitted

    t0 = time.perf_counter()
    fitted = method.fit(records)
    seconds = time.perf_counter() - t0
    s = score_fitted(fitted, records, truths, windows=windows, simulate=False, fit_time_s=seconds)
    flagged = 0 if math.isnan(s["coverage"]) else int(round(s["coverage"] * s["n_scored"]))
    right = 0 if not flagged else int(round(s["accuracy_identifiable"] * flagged))
    evidence = model_evidence(fitted) or {}
    smoothing = getattr(getattr(fitted, "model", fitted), "fitted_wind_smoothing", None)
    return {"error": s["rhs_error_true_AU_energy"], "curve_error": s["curve_error_energy"], "flags": flagged,
            "right": right, "coverage": s["coverage"], "fit_s": seconds, "chosen": str(evidence.get("chosen", "")),
            "smoothing": float(smoothing()) if callable(smoothing) else math.nan}


def labelled_row(task: dict) -> tuple[dict, dict]:
    """The draw's family labels and the start of its row: ``draw``, ``eiv`` (the kind of errors in the wind) and
    ``n_sections``."""
    from vivbench.synth.family import draw_bridge

    labels = draw_bridge(task["split"], task["draw"]).labels
    return labels, {"draw": task["draw"], "eiv": str(labels["eiv"]), "n_sections": int(labels["n_sections"])}


def draw_inputs(task: dict) -> tuple[list, list, list]:
    """The draw's records, truths and windows (:func:`capped_draw`, which reads a draw directory copied from another
    study of the same caps instead of generating and identifying it again)."""
    return capped_draw(task)
