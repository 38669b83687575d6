"""Does the twin predict? Draws of the generator family treated as field campaigns.

For each draw of a split of the family (:func:`vivbench.synth.family.draw_bridge`; the evaluation
split by default) the check runs what a field user runs: generate the draw's campaign (its truth
set aside), ``vivbench identify`` with the default settings, ``vivbench pool`` with its defaults
(the held-out selection of varying-coefficient models; ``bootstrap`` replicates), then
:func:`vivbench.validate.twin.run_twin` with the draw's structural properties
(:func:`vivbench.validate.greybox_method.structural_properties`, never its aerodynamics) and
``n_twins`` twin draws. The *actual* figures score the campaign model against the draw's own truth;
a figure is predicted when it lies within the twin's 90 % range of a campaign. The result is the
share of draws whose actual figure lies inside, per figure (the aim: at least 80 %).

One task is one family draw; finished draws are journalled (``OUT/twin_check.jsonl``) and the
run resumes; ``OUT/twin_check.json`` and ``OUT/twin_check.md`` are rewritten atomically from the
journal alone.
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vivbench.analysis.identify import IdentifyConfig, identify_files
from vivbench.analysis.pool import pool_results
from vivbench.analysis.selection import varying_selection
from vivbench.core.errors import InputError, error_line
from vivbench.core.lock import exclusive_directory
from vivbench.io.campaign_model import MODEL_NAME, write_campaign_regimes
from vivbench.io.netcdf import atomic_path
from vivbench.synth.campaign import generate_campaign
from vivbench.synth.family import SPLITS, draw_bridge
from vivbench.validate.journal import check_record, counting_progress, run_journalled, task_directory
from vivbench.validate.journal import load as journal_load
from vivbench.validate.methods import scoring_inputs
from vivbench.validate.study import check_draws
from vivbench.validate.study_report import PROMISE_MIN_FLAGS, PROMISE_SHARE
from vivbench.validate.twin import METRIC_NAMES, TwinConfig, read_twin, run_twin
from vivbench.validate.twin_chain import chain_scores
from vivbench.validate.twin_mirror import TwinBridge

__all__ = ["CHECKED_METRICS", "TwinCheckConfig", "run_twin_check", "run_twin_check_task", "twin_check_markdown"]

#: The figures whose prediction is checked.
CHECKED_METRICS = ("flagged_right_share", "coverage", "rhs_error_true_AU_energy", "rhs_error_true_AU_median",
                   "curve_error_total", "curve_error_energy")
_COLUMNS = ("task_id", "draw", "actual", "inside")


@dataclass(frozen=True, kw_only=True)
class TwinCheckConfig:
    """What the check runs.

    Attributes
    ----------
    split : family split ("evaluation" by default: reported only, never tuned on)
    draws : family draw numbers
    n_twins : twin draws per family draw
    max_events, max_duration : caps on each family campaign (events; s), None: the draw's own
    bootstrap : block-bootstrap replicates of ``pool``'s campaign model (its default is 100)
    """

    split: str = "evaluation"
    draws: tuple[int, ...] = (0, 1, 2)
    n_twins: int = 3
    max_events: int | None = None
    max_duration: float | None = None
    bootstrap: int = 100

    def __post_init__(self) -> None:
        if self.split not in SPLITS:
            raise InputError(f"split must be one of {', '.join(SPLITS)}; got {self.split!r}")
        object.__setattr__(self, "draws", check_draws(self.draws))
        TwinConfig(n_draws=self.n_twins)
        if not (isinstance(self.bootstrap, int) and self.bootstrap >= 2):
            raise InputError(f"bootstrap must be an integer >= 2; got {self.bootstrap!r}")


@dataclass(frozen=True, kw_only=True)
class _Task:
    split: str
    draw: int
    n_twins: int
    max_events: int | None
    max_duration: float | None
    bootstrap: int
    work_root: str | None = None


def run_twin_check_task(task: _Task) -> dict[str, Any]:
    """One family draw: the field chain, its actual figures, its twin and whether they agree."""
    draw = draw_bridge(task.split, task.draw)
    campaign = draw.campaign_config(max_events=task.max_events, max_duration=task.max_duration)
    root = task_directory(task.work_root, f"check{task.draw:05d}-")
    try:
        made = generate_campaign(campaign, root / "campaign", workers=1)
        identify = IdentifyConfig()
        written, _ = identify_files(made.files, root / "identify", identify, workers=1)
        if not written:
            raise InputError(f"no event of {task.split} draw {task.draw} could be identified")
        results = sorted(written, key=lambda p: p.name)
        model = varying_selection(n_bootstrap=task.bootstrap, seed=0)
        ds = pool_results(results, model)  # fits the model in place, as vivbench pool does
        write_campaign_regimes(ds, root / "identify")
        model.save(root / "identify" / MODEL_NAME)
        ids = {p.name.removesuffix(".identify.nc") for p in results}
        events = sorted((f for f in made.files if f.stem in ids), key=lambda p: p.name)
        records, truths, windows = scoring_inputs(events, results)
        actual = chain_scores(model, records, truths, windows, tau=identify.tau)
        s = draw.config.structure
        bridge = TwinBridge(mass=s.mass, depth=s.depth, damping_ratio=s.damping_ratio, air_density=s.air_density,
                            frequency=s.frequency, mode_shape=s.mode_shape, tributary_lengths=s.tributary_lengths,
                            span_length=s.span_length)
        run_twin(root / "campaign", root / "identify", bridge, root / "twin",
                 config=TwinConfig(n_draws=task.n_twins, seed=task.draw))
        twin = read_twin(root / "twin")
        expected = twin["expected"]
        twin_values = {m: [d["scores"][m] for d in twin["draws"]] for m in CHECKED_METRICS}
    except Exception as exc:
        raise RuntimeError(error_line(exc).replace(str(root), "<draw>")) from None
    finally:
        shutil.rmtree(root, ignore_errors=True)
    inside = {}
    for m in CHECKED_METRICS:
        lo, hi, a = expected[m]["predict_low"], expected[m]["predict_high"], actual[m]
        inside[m] = None if not all(math.isfinite(x) for x in (lo, hi, a)) else bool(lo <= a <= hi)
    return {"draw": task.draw, "n_events": campaign.n_events, "labels": draw.labels, "actual": actual,
            "expected": {m: expected[m] for m in CHECKED_METRICS}, "twin_values": twin_values,
            "twin_errors": twin.get("errors", {}), "inside": inside, "twin_promise": twin.get("promise"),
            "twin_nuisances": [d.get("nuisances") for d in twin["draws"]]}


#: Figures that are shares: their range's width is high - low; the errors' is the factor high / low.
_SHARES = ("flagged_right_share", "coverage")


def _median_width(metric: str, ranges: list[dict]) -> float:
    """Median width of the twin's ranges: high - low for shares, high / low for errors (NaN when low is 0)."""
    if metric in _SHARES:
        widths = [e["predict_high"] - e["predict_low"] for e in ranges]
    else:
        widths = [e["predict_high"] / e["predict_low"] if e["predict_low"] > 0 else math.nan for e in ranges]
    return float(np.median(widths)) if widths else math.nan


def _summary(config: TwinCheckConfig, done: dict[int, dict], failed) -> dict:
    rows = [done[d] for d in config.draws if d in done]
    shares = {}
    for m in CHECKED_METRICS:
        assessed = [r for r in rows if r["inside"][m] is not None]
        flags = [r["inside"][m] for r in assessed]
        above = sum(1 for r in assessed if not r["inside"][m] and r["actual"][m] > r["expected"][m]["predict_high"])
        shares[m] = {"inside": int(sum(flags)), "assessed": len(flags), "above": above,
                     "below": len(flags) - int(sum(flags)) - above,
                     "share": (sum(flags) / len(flags)) if flags else math.nan,
                     "median_width": _median_width(m, [r["expected"][m] for r in assessed])}
    return {"config": asdict(config), "draws": rows, "failed": sorted(failed), "share_inside": shares,
            "promise": _promise_rows(rows),
            "aim": "the actual figure within the twin's 90 % range on at least 80 % of the draws"}


def _promise_rows(rows: list[dict]) -> list[dict]:
    """The campaigns that flagged enough windows to test the verdict's promise, beside their twin's count
    (:func:`vivbench.validate.twin.twin_promise`; absent from rows journalled before it was kept)."""
    out = []
    for r in rows:
        flags, share = r["actual"].get("n_flagged", 0), r["actual"].get("flagged_right_share", math.nan)
        if not (flags >= PROMISE_MIN_FLAGS and math.isfinite(share)) or not r.get("twin_promise"):
            continue
        t = r["twin_promise"]
        out.append({"draw": r["draw"], "flags": int(flags), "share_right": float(share),
                    "broken": bool(share < PROMISE_SHARE), "twins_tested": t["tested"], "twins_broken": t["broken"],
                    "broken_upper": t["broken_upper"]})
    return out


def twin_check_markdown(summary: dict) -> str:
    """``twin_check.md``: per figure, the share of draws whose actual value the twin's range holds."""
    c = summary["config"]
    caps = ", ".join(f"{k} {c[k]}" for k in ("max_events", "max_duration") if c[k] is not None)
    drawn = (" Each twin draws what a field user cannot measure (the errors in the wind, buffeting, a yaw effect) "
             "from the generator family's priors; the values drawn are in the summary's `twin_nuisances`."
             if any(n for r in summary["draws"] for n in r.get("twin_nuisances", [])) else "")
    lines = ["# Does the twin predict?", "",
             f"{len(summary['draws'])} {c['split']} draws of the generator family treated as field campaigns "
             f"({', '.join(map(str, c['draws']))}), {c['n_twins']} twin draws each, pool bootstrap {c['bootstrap']}"
             + (f"; capped campaigns ({caps})" if caps else "") + "." + drawn, "",
             "| figure | actual within the twin's 90 % range | above the range | below it "
             "| median width of the range |", "|---|---|---|---|---|"]
    for m, s in summary["share_inside"].items():
        share = "n/a" if not math.isfinite(s["share"]) else f"{s['share']:.0%}"
        width = s.get("median_width", math.nan)
        width = "n/a" if not math.isfinite(width) else (f"{width:.2f}" if m in _SHARES else f"factor {width:.3g}")
        lines.append(f"| {METRIC_NAMES[m]} | {s['inside']} of {s['assessed']} ({share}) | {s.get('above', 'n/a')} | "
                     f"{s.get('below', 'n/a')} | {width} |")
    lines += ["", "| draw | figure | actual | twin's 90 % range | inside |", "|---|---|---|---|---|"]
    for r in summary["draws"]:
        for m in CHECKED_METRICS:
            e, a = r["expected"][m], r["actual"][m]
            lines.append(f"| {r['draw']} | {m} | {a:.3g} | {e['predict_low']:.3g} - {e['predict_high']:.3g} | "
                         f"{'n/a' if r['inside'][m] is None else ('yes' if r['inside'][m] else 'no')} |")
    promise = summary.get("promise") or []
    if promise:
        broken = [p for p in promise if p["broken"]]
        seen = [p for p in broken if p["twins_broken"] > 0]
        lines += ["", f"The verdict's promise (at least {PROMISE_SHARE * 100:.0f} % of at least {PROMISE_MIN_FLAGS} "
                  "flags right): "
                  f"{len(promise)} campaigns flagged enough windows to test it, {len(broken)} broke it, and the twins "
                  f"of {len(seen)} of those saw it broken at least once. The bound is the twin's one-sided 95 % upper "
                  "bound of the chance that a campaign like this one breaks the promise.", "",
                  "| draw | flags | share right | broken | twin draws tested | broken in the twins | bound |",
                  "|---|---|---|---|---|---|---|"]
        for p in promise:
            bound = "n/a" if not math.isfinite(p["broken_upper"]) else f"{p['broken_upper'] * 100:.0f} %"
            lines.append(f"| {p['draw']} | {p['flags']} | {p['share_right']:.3f} | {'yes' if p['broken'] else 'no'} | "
                         f"{p['twins_tested']} | {p['twins_broken']} | {bound} |")
    failed_twins = [f"draw {r['draw']}: {len(r.get('twin_errors', {}))} of {c['n_twins']}" for r in summary["draws"]
                    if r.get("twin_errors")]
    if failed_twins:
        lines += ["", "Twin draws that failed (their figures are left out of the range): " + "; ".join(failed_twins) + "."]
    lines += ["", "The twin's 90 % range is the normal-theory prediction interval of one more campaign over the twin "
              "draws (of the logarithm for the errors); with few twin draws it is wide, so the share inside says "
              "little about a twin with many draws. Its width is high - low for the shares and the factor high / low "
              "for the errors (n/a where the range reaches 0)."]
    if summary["failed"]:
        lines += ["", f"Failed draws (retried by the next run): {', '.join(map(str, summary['failed']))}."]
    return "\n".join(lines) + "\n"


def run_twin_check(config: TwinCheckConfig, out_dir, *, workers: int = 1,
                   progress: Callable[[int, int], None] | None = None) -> tuple[Path, Path, dict[int, str]]:
    """Run (or resume) the check; returns the paths of ``twin_check.json`` and ``twin_check.md`` and the failures."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    data = {k: v for k, v in asdict(config).items() if k != "draws"}
    fingerprint = hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()
    with exclusive_directory(out, ".twin_check.lock", "twin check"):
        check_record(out / "twin_check_config.json", fingerprint, data,
                     "this directory holds a check of another split, twin count, caps or bootstrap; use another --out")
        journal = out / "twin_check.jsonl"
        done, _ = journal_load(journal, n_tasks=2**31, columns=_COLUMNS)
        work = out / ".work"
        shutil.rmtree(work, ignore_errors=True)
        pending = [_Task(split=config.split, draw=d, n_twins=config.n_twins, max_events=config.max_events,
                         max_duration=config.max_duration, bootstrap=config.bootstrap, work_root=str(work))
                   for d in config.draws if d not in done]
        if progress is not None:
            progress(len(config.draws) - len(pending), len(config.draws))
        try:
            _, failures = run_journalled(
                run_twin_check_task, pending, journal, done, task_id=lambda t: t.draw,
                failed_row=lambda t: {"draw": t.draw, "actual": {}, "inside": {}}, workers=workers,
                progress=None if progress is None else
                counting_progress(progress, len(config.draws) - len(pending), len(config.draws)))
        finally:
            shutil.rmtree(work, ignore_errors=True)
        rows = {d: {k: v for k, v in r.items() if k != "task_id"} for d, r in done.items()}
        summary = _summary(config, rows, failures)
        path, page = out / "twin_check.json", out / "twin_check.md"
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(summary, indent=1, sort_keys=True, allow_nan=True) + "\n", encoding="utf-8")
        with atomic_path(page) as tmp:
            tmp.write_text(twin_check_markdown(summary), encoding="utf-8")
    return path, page, failures
