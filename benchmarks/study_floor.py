"""Diagnose the error floor of the varying-coefficient model on a realistic campaign.

Run::

    .venv/bin/python benchmarks/study_floor.py --campaign demo/campaign --results demo/identify

The varying-coefficient model fitted on the truth's OWN (A, U, dA) still had a
median dA/dt error of about 0.17 on realistic campaigns, so the floor is a
model-class problem, not errors-in-variables. This script splits that error:

- by window activity: the window's true dA/dt RMS relative to its event's RMS
  (a relative error on near-zero dynamics says little);
- by the window's yaw (the wind's angle to the span's normal, measured from
  the anemometers' low-passed u, v and the span azimuth, as the identification
  can): the realistic aerodynamics fall off with yaw, which U = V |sin theta|
  alone does not carry;
- by section;

and scores the same fits with a second metric that does not blow up on
near-zero dynamics: the window's RMS error divided by its event's RMS of the
true dA/dt (``err_event_scaled``). Each model is fitted on the truth (A, U,
dA) and, where it applies, with the measured yaw as a second covariate.
Nothing is asserted; the table is printed and written to
``benchmarks/out/floor.json``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from study_misspecification import _window_sums, load_campaign  # noqa: E402

from vivbench.models import VaryingCoefficientSINDy  # noqa: E402

OUT = Path(__file__).resolve().parent / "out"


def window_errors(model, events):
    """Per (window, section) of every event: relative error, event-scaled error, activity, yaw, section."""
    rows = []
    for ev in events:
        trec, ws, we = ev["truth_rec"], ev["ws"], ev["we"]
        t, true = trec.t, trec.dA
        pred = model.predict(trec)
        ok = np.isfinite(pred) & np.isfinite(true)
        num = _window_sums(np.where(ok, (pred - true) ** 2, 0.0), t, ws, we)
        den = _window_sums(np.where(ok, true**2, 0.0), t, ws, we)
        cnt = _window_sums(ok.astype(float), t, ws, we)
        yaw = getattr(trec, "yaw", None)
        yw = (_window_sums(np.where(ok, np.abs(yaw), 0.0), t, ws, we) / np.maximum(cnt, 1)
              if yaw is not None else np.full(num.shape, np.nan))
        event_ms = np.nanmean(np.where(ok, true, np.nan) ** 2, axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = np.sqrt(num / den)
            scaled = np.sqrt(num / np.maximum(cnt, 1) / event_ms)
            act = np.sqrt(den / np.maximum(cnt, 1) / event_ms)
        sec = np.broadcast_to(np.arange(num.shape[1]), num.shape)
        keep = cnt > 0
        rows.append(np.stack([rel[keep], scaled[keep], act[keep], yw[keep], sec[keep]], axis=1))
    return np.concatenate(rows)


def summarise(w: np.ndarray) -> dict:
    rel, scaled, act, yaw, sec = w.T
    dyn = act >= 0.1
    out = {"median_rel_dyn": float(np.median(rel[dyn])), "median_scaled_dyn": float(np.median(scaled[dyn])),
           "median_scaled_all": float(np.median(scaled)), "n_dyn": int(dyn.sum())}
    for lo, hi in ((0.1, 0.3), (0.3, 1.0), (1.0, np.inf)):
        s = dyn & (act >= lo) & (act < hi)
        out[f"rel_act_{lo:g}-{hi:g}"] = [float(np.median(rel[s])) if s.any() else None, int(s.sum())]
    if np.isfinite(yaw).any():
        for lo, hi in ((0, 5), (5, 10), (10, 15), (15, 90)):
            s = dyn & (yaw >= lo) & (yaw < hi)
            out[f"rel_yaw_{lo}-{hi}"] = [float(np.median(rel[s])) if s.any() else None, int(s.sum())]
    for k in np.unique(sec).astype(int):
        s = dyn & (sec == k)
        out[f"rel_S{k + 1}"] = float(np.median(rel[s]))
    return out


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaign", required=True, type=Path)
    parser.add_argument("--results", required=True, type=Path)
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    _measured, events = load_campaign(args.campaign, args.results)  # both records with the measured yaw
    print(f"{args.campaign}: {len(events)} events loaded in {time.perf_counter() - t0:.1f} s", flush=True)
    truth = [ev["truth_rec"] for ev in events]
    measured = [ev["measured"] for ev in events]
    out = {}
    specs = [("VCM (U only)", dict(n_bootstrap=0)),
             ("VCM + yaw (sin^2 psi, degree 1)", dict(n_bootstrap=0, yaw_degree=1)),
             ("VCM + yaw (sin^2 psi, degree 2)", dict(n_bootstrap=0, yaw_degree=2))]
    for name, kw in specs:
        for data, recs in (("truth", truth), ("measured", measured)):
            t1 = time.perf_counter()
            model = VaryingCoefficientSINDy(**kw).fit(recs)
            row = summarise(window_errors(model, events))
            row["fit_s"] = round(time.perf_counter() - t1, 1)
            row["n_basis"] = model.n_basis_.tolist()
            out[f"{name} fitted on {data}"] = row
            print(f"{name} fitted on {data}: {json.dumps(row)}", flush=True)
    OUT.mkdir(exist_ok=True)
    (OUT / "floor.json").write_text(json.dumps(out, indent=2) + "\n")
    return out


if __name__ == "__main__":
    main()
