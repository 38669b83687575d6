"""Event detection on synthetic continuous logs: boundary F1 within a 2-minute margin, over seeds.

Run::

    .venv/bin/python benchmarks/run_study.py event_detection --seeds 0 1 2 3 4 --days 2
    .venv/bin/python benchmarks/run_study.py event_detection --seeds 0 --days 1 --files

Each seed simulates a log of ``--days`` days (``vivbench.synth.ContinuousLogConfig``:
six VIV events and six wind-only gusts a day between quiet periods, the default
bridge at 32 Hz wind and 50 Hz acceleration), detects its events and scores
the detected boundaries against the true ones (true amplitude above 5 mm) with
``vivbench.validate.boundary_f1`` within 120 s. Two detectors are scored: the
default (threshold 12 times each section's noise floor, from the log itself)
and one given the truth's level as an absolute threshold (``threshold_m =
0.005``), which isolates the estimation of the amplitude from the choice of
the threshold; the F1 of other factors (``--factors``) shows how much the
score depends on the default. The default factor was chosen on seeds 100 to
102, which the reported seeds (0 to 4) do not include. By default the detector reads the simulated arrays; with
``--files`` the log is written as daily CSV files (local time +08:00, km/h,
milli-g) and read back through its mapping by ``find_events``, as ``vivbench
events`` does. ``run_study.py`` writes the figures to ``docs/results/studies/event_detection.md``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import asdict  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from vivbench.preprocess import EventDetectionConfig, detect_events, find_events  # noqa: E402
from vivbench.synth import ContinuousLogConfig, generate_continuous_log, write_continuous_log  # noqa: E402
from vivbench.validate import boundary_f1  # noqa: E402

OUT = Path(__file__).resolve().parent / "out"
MARGIN_S = 120.0


def _score(truth: np.ndarray, found: np.ndarray) -> dict:
    s = boundary_f1(truth, found, margin_s=MARGIN_S)
    return {**asdict(s), "intervals": np.round(found, 1).tolist()}


def run_seed(seed: int, days: float, files: bool, factors: list) -> dict:
    t0 = time.perf_counter()
    log = generate_continuous_log(ContinuousLogConfig(duration_s=round(days * 86400.0), seed=seed))
    t_sim = time.perf_counter() - t0
    configs = {"default": EventDetectionConfig(),
               "truth_level": EventDetectionConfig(threshold_m=log.config.event_amplitude_m)}
    configs.update({f"factor_{f:g}": EventDetectionConfig(threshold_factor=f) for f in factors})
    row = {"seed": seed, "days": days, "n_true_events": int(len(log.events)),
           "true_intervals": np.round(log.events, 1).tolist(), "simulate_s": round(t_sim, 1)}
    t0 = time.perf_counter()
    if files:
        with tempfile.TemporaryDirectory() as tmp:
            mapping = write_continuous_log(log, Path(tmp) / "log")
            row["write_s"] = round(time.perf_counter() - t0, 1)
            t0 = time.perf_counter()
            for name, cfg in configs.items():
                if name.startswith("factor_"):
                    continue  # the sensitivity to the factor is measured on the arrays
                found = find_events(mapping, Path(tmp) / f"events_{name}", cfg).detection
                row[name] = _score(log.events, found.intervals)
    if not files or factors:
        for name, cfg in configs.items():
            if files and not name.startswith("factor_"):
                continue
            found = detect_events(log.accel_time, log.acc, cfg)
            row[name] = _score(log.events, found.intervals)
    row["detect_s"] = round(time.perf_counter() - t0, 1)
    return row


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    p.add_argument("--days", type=float, default=2.0)
    p.add_argument("--files", action="store_true", help="write daily CSV files and detect through the mapping")
    p.add_argument("--factors", type=float, nargs="*", default=[8.0, 10.0, 15.0, 20.0],
                   help="other threshold factors scored for comparison")
    p.add_argument("--out", type=Path, default=OUT / "event_detection.json")
    args = p.parse_args(argv)
    rows = []
    for seed in args.seeds:
        row = run_seed(seed, args.days, args.files, args.factors)
        rows.append(row)
        print(f"seed {seed}: {row['n_true_events']} true events; default F1 {row['default']['f1']:.3f} "
              f"(P {row['default']['precision']:.3f}, R {row['default']['recall']:.3f}); at the truth's level "
              f"F1 {row['truth_level']['f1']:.3f}; simulate {row['simulate_s']} s, detect {row['detect_s']} s", flush=True)
    summary = {}
    for name in ["default", "truth_level"] + [f"factor_{f:g}" for f in args.factors]:
        tp = sum(r[name]["true_positives"] for r in rows)
        n_true = sum(r[name]["n_true"] for r in rows)
        n_det = sum(r[name]["n_detected"] for r in rows)
        f1s = [r[name]["f1"] for r in rows]
        pooled = 2 * tp / (n_true + n_det) if n_true + n_det else 1.0
        summary[name] = {"pooled_f1": pooled, "min_f1": min(f1s), "mean_f1": float(np.mean(f1s)),
                         "true_positives": tp, "n_true": n_true, "n_detected": n_det}
        print(f"{name}: pooled F1 {pooled:.3f} over {len(rows)} seeds x {args.days:g} days "
              f"({tp} of {n_true} true boundaries, {n_det} detected); per seed min {min(f1s):.3f}, mean {np.mean(f1s):.3f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"margin_s": MARGIN_S, "files": args.files, "summary": summary, "seeds": rows},
                                   indent=1))
    print(f"wrote {args.out}")
    return {"margin_s": MARGIN_S, "days": args.days, "files": args.files, "seeds": args.seeds,
            "rows": [{"detector": name, **{k: (round(v, 3) if isinstance(v, float) else v) for k, v in row.items()}}
                     for name, row in summary.items()]}


if __name__ == "__main__":
    main()
