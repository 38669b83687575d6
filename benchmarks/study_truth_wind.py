"""Study: how much of the campaign models' error and of their verdicts' failures comes from the errors in the wind.

Run::

    python benchmarks/run_study.py truth_wind --split evaluation --draws 30-59 --out DIR \
        [--methods varying,greybox] [--measured STUDY_DIR] [--max-events N] [--max-duration MIN] [--workers 2]

The same draws of the generator family are studied twice by :func:`vivbench.validate.run_study`:
once as a user has them, on the wind the anemometers measured (``DIR/measured``, or an existing
``vivbench study`` directory of the same split, caps and identification given by ``--measured``,
whose rows of these methods and draws are read), and once on the wind the truth's dynamics sees
(``DIR/truth``, ``vivbench study --wind-source truth``: every record's wind replaced by the
truth's, :func:`vivbench.validate.record_with_truth_wind`). Nothing else differs: the same
campaigns, identification, methods and verdicts.

No user has the truth's wind. The pair separates the two sources of a method's error: what is left
on the truth's wind is its model class and the errors in the measured amplitude; the difference is
the errors in the wind (the anemometers' point turbulence, the deck's tributary averaging, the
anemometers' distance from the deck). Per method the page gives, for each wind, the
energy-weighted relative dA/dt error and curve error on the truth's own (A, U) over the draws
(median, 90th percentile, worst), the draws with at least 20 flagged window-equations and how many
keep the verdict's promise (at least 95 % of the flags right), and per draw both rows.

The summary also gives, from each study's ``summary.json``, the draws where the yaw matters and
the yaw covariate was chosen, and the change scan's false alarms and detected damping steps.

``--max-events`` and ``--max-duration`` (minutes) cap the campaigns (the page then says so). Both
study directories are resumable: rerunning the command continues them, and when both are complete
it only reads them (the page's wall time is then that of the reading).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import csv  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from vivbench.core.errors import InputError  # noqa: E402
from vivbench.validate.study import StudyConfig, parse_draws, run_study  # noqa: E402
from vivbench.validate.study_report import PROMISE_MIN_FLAGS, PROMISE_SHARE, study_summary  # noqa: E402

#: Scores compared between the two winds (study.csv columns).
SCORES = ("rhs_error_true_AU_energy", "curve_error_energy")


def _num(text) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


def _count(text) -> int:
    x = _num(text)
    return int(x) if math.isfinite(x) else 0


def _read_rows(study_dir: Path, methods, draws) -> dict[tuple[int, str], dict]:
    """(draw, method) -> the study.csv row, for the given methods and draws; InputError when one is missing."""
    path = Path(study_dir) / "study.csv"
    if not path.exists():
        raise InputError(f"{path}: no study table (run vivbench study into {study_dir} first)")
    with open(path, encoding="utf-8") as fh:
        rows = {(int(r["draw"]), r["method"]): r for r in csv.DictReader(fh)}
    missing = [(d, m) for d in draws for m in methods if (d, m) not in rows]
    if missing:
        raise InputError(f"{path}: no row for draw {missing[0][0]}, method {missing[0][1]} "
                         f"({len(missing)} missing); study those draws and methods there first")
    return {(d, m): rows[(d, m)] for d in draws for m in methods}


def _check_measured(study_dir: Path, config: StudyConfig) -> None:
    """InputError unless ``study_dir`` is a study on the measured wind of ``config``'s split, caps and
    identification."""
    path = Path(study_dir) / "study_config.json"
    if not path.exists():
        raise InputError(f"{path}: not a vivbench study directory")
    record = json.loads(path.read_text(encoding="utf-8"))
    data = record.get("config", record)
    want = config.to_dict()
    for key in ("split", "max_events", "max_duration_s", "identify", "tau"):
        if data.get(key) != want.get(key):
            raise InputError(f"{path}: its {key} is {data.get(key)!r}, this study's is {want.get(key)!r}; "
                             "the measured study must differ from this one by its wind only")
    if data.get("wind_source", "measured") != "measured" or data.get("anemometer_span") is not None:
        raise InputError(f"{path}: not a study on the measured wind with one anemometer per section")


def _broken(rows) -> list[int]:
    """The draws with enough flags whose share of right flags is below the promise."""
    return [int(r["draw"]) for r in rows
            if _count(r["n_flagged"]) >= PROMISE_MIN_FLAGS and not _num(r["flagged_right_share"]) >= PROMISE_SHARE]


def _entry(block: dict) -> dict:
    """The figures of one method and wind from its :func:`vivbench.validate.study_summary` block."""
    out = {}
    for key in SCORES:
        d = block["scores"][key]
        out.update({f"{key}_median": _num(d["median"]), f"{key}_p90": _num(d["p90"]),
                    f"{key}_worst": _num(d["worst"])})
    pr, ch, ca = block["promise"], block["choices"], block["changes"]
    out.update(promise_draws=pr["draws_with_enough_flags"], promise_kept=pr["draws_kept"],
               yaw_matters_draws=ch["matters_draws"], yaw_matters_chosen=ch["matters_yaw_chosen"],
               yaw_chosen=ch["yaw_chosen"], draws_without_change=ca["draws_without_change"],
               false_alarms=ca["false_alarms"], draws_with_step=ca["draws_with_step"], steps_detected=ca["detected"],
               regimes_withheld=block["withheld"]["withheld"])
    return out


def summarise(config: StudyConfig, measured: dict, truth: dict) -> tuple[list[dict], list[dict]]:
    """Per method and wind: the study summary (:func:`vivbench.validate.study_summary`) of the rows of ``config``'s
    draws (scores' spread, promise, covariates chosen, change scan) and the draws that break the promise; per
    draw and method: both winds' rows. ``measured``, ``truth``: (draw, method) -> ``study.csv`` row."""
    methods, draws = config.methods, config.draws
    blocks = {wind: study_summary(config.to_dict(), list(table.values()))["methods"]
              for wind, table in (("measured", measured), ("truth", truth))}
    summary, rows = [], []
    for m in methods:
        for wind, table in (("measured", measured), ("truth", truth)):
            mine = [table[(d, m)] for d in draws]
            summary.append({"method": m, "wind": wind, **_entry(blocks[wind][m]["all"]),
                            "promise_broken": _broken(mine),
                            "flagged_median": float(np.median([_num(r["n_flagged"]) for r in mine]))})
        pairs = [(_num(measured[(d, m)][SCORES[0]]), _num(truth[(d, m)][SCORES[0]])) for d in draws]
        summary[-1]["draws_lower_on_truth_wind"] = sum(1 for a, b in pairs if b < a)
        for d in draws:
            a, b = measured[(d, m)], truth[(d, m)]
            rows.append({"draw": d, "method": m, "eiv": a["eiv"], "n_sections": _count(a["n_sections"]),
                         "n_events": _count(a["n_events"]), "point_intensity": _num(a["point_intensity"]),
                         "dA_error_measured": _num(a[SCORES[0]]), "dA_error_truth": _num(b[SCORES[0]]),
                         "flags_measured": _count(a["n_flagged"]), "right_measured": _num(a["flagged_right_share"]),
                         "flags_truth": _count(b["n_flagged"]), "right_truth": _num(b["flagged_right_share"]),
                         "error": a["error"] or b["error"]})
    return summary, rows


def _scan_text(s: dict) -> str:
    """The change scan's clause of a finding ("" for a method without a scan on these draws)."""
    if not s["draws_without_change"] and not s["draws_with_step"]:
        return ""
    return (f"; the change scan alarmed on {s['false_alarms']} of {s['draws_without_change']} draws without a "
            f"change and detected {s['steps_detected']} of {s['draws_with_step']} damping steps")


def findings(summary: list[dict], methods, n_draws: int, split: str, caps: str) -> list[str]:
    """Sentences generated from the figures."""
    out = [f"{n_draws} {split} draws{caps}, each studied on the measured wind and on the truth's."]
    by = {(s["method"], s["wind"]): s for s in summary}
    key = SCORES[0]
    for m in methods:
        a, b = by[(m, "measured")], by[(m, "truth")]
        out.append(f"{m}: energy-weighted dA/dt error median {a[key + '_median']:.3f} on the measured wind and "
                   f"{b[key + '_median']:.3f} on the truth's (90th percentile {a[key + '_p90']:.3f} and "
                   f"{b[key + '_p90']:.3f}, worst {a[key + '_worst']:.3f} and {b[key + '_worst']:.3f}); lower on "
                   f"the truth's wind on {b['draws_lower_on_truth_wind']} of {n_draws} draws.")
        for wind, s in (("measured", a), ("truth's", b)):
            broken = (f"broken on draws {', '.join(map(str, s['promise_broken']))}" if s["promise_broken"]
                      else "broken on none")
            out.append(f"{m}, {wind} wind: the promise kept on {s['promise_kept']} of {s['promise_draws']} draws "
                       f"with at least {PROMISE_MIN_FLAGS} flags ({broken}); the yaw covariate chosen on "
                       f"{s['yaw_matters_chosen']} of the {s['yaw_matters_draws']} draws where the yaw matters"
                       + _scan_text(s) + ".")
    return out


def main(argv=None) -> dict:
    from _family_args import family_parser

    parser = family_parser(__doc__.splitlines()[0])
    parser.add_argument("--methods", default="varying,greybox", help="comma-separated study methods")
    parser.add_argument("--measured", type=Path, default=None,
                        help="an existing vivbench study directory on the measured wind (same split, caps and "
                             "identification) to read instead of running it into OUT/measured")
    args = parser.parse_args(argv)
    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    draws = parse_draws(args.draws)
    common = dict(split=args.split, draws=draws, methods=methods, max_events=args.max_events,
                  max_duration=None if args.max_duration is None else args.max_duration * 60.0)
    failed = []
    if args.measured is None:
        measured_dir = args.out / "measured"
        failed += sorted(run_study(StudyConfig(**common), measured_dir, workers=args.workers).failures)
    else:
        measured_dir = args.measured
        _check_measured(measured_dir, StudyConfig(**common))
    truth_dir = args.out / "truth"
    failed += sorted(run_study(StudyConfig(**common, wind_source="truth"), truth_dir, workers=args.workers).failures)
    if failed:
        raise InputError(f"draws {sorted(set(failed))} failed; run the command again to retry them")
    measured = _read_rows(measured_dir, methods, draws)
    truth = _read_rows(truth_dir, methods, draws)
    summary, rows = summarise(StudyConfig(**common), measured, truth)
    caps = "".join(f" (capped: {c})" for c in [", ".join(
        ([f"at most {args.max_events} events"] if args.max_events is not None else [])
        + ([f"events at most {args.max_duration:g} min"] if args.max_duration is not None else []))] if c)
    return {"findings": findings(summary, methods, len(draws), args.split, caps), "split": args.split,
            "draws": list(draws),
            "methods": list(methods), "max_events": args.max_events, "max_duration_min": args.max_duration,
            "summary": summary, "rows": rows}


if __name__ == "__main__":
    main()
