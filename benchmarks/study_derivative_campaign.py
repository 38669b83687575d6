"""Benchmark: dA/dt of the identification chain against the true averaged dA/dt, on campaign envelopes.

Run: ``.venv/bin/python benchmarks/study_derivative_campaign.py [--campaign DIR]
[--events N] [--clean N]``. The default campaign (31 events, seed 0) is read
from ``--campaign`` or from ``benchmarks/out/campaign`` (gitignored; made with
``python -m vivbench.cli synth --out benchmarks/out/campaign --workers 2``
when missing).

Each event is preprocessed exactly as ``identify_event`` does (raw-input
checks and despiking, band-limited integration, Hilbert envelope, 4 Hz grid),
each segment of A is differentiated by each method, and the result is compared
with the truth on the grid times the two grids share (the truth is on a 0.5 s
grid, docs/concepts.md (the truth): dA_k/dt is the sum over orders of ``r``). Score per event:
relative RMS error of dA/dt per section, RMS over the three sections.

Methods: the band-limited setting ``Derivative.for_envelope()`` =
``Derivative(time_scale=20, huber=10, noise_scale=10)`` (Huber-TV, noise level
measured at the regulariser's time scale), the chain's default; the
white-noise rule ``Derivative()`` (exact TV, 10 s, white-noise estimate),
which the campaign model uses; exact TV with the band noise rule
(``Derivative(time_scale=20, huber=0, noise_scale=10)``); finite differences; the
Savitzky-Golay default; and, as a reference that no automatic rule can beat
without the truth, Huber-TV tuned per event against the truth on a grid of
(time_scale, huber) with noise_scale = time_scale / 2, tuned on the mid-span
section and scored on all three.

A noise-free variant (no sensor noise, quantisation, anemometer error,
turbulence, buffeting or unlocked shedding: the clean campaign of
``bench_identify.py``) of the first ``--clean`` events is generated in a
temporary directory and scored the same way, to check that the automatic rule
does not over-smooth clean envelopes.

Nothing is asserted; the table is printed and the figures are returned and
written to ``benchmarks/out/derivative_campaign.json``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from vivbench.preprocess.derivative import Derivative
from vivbench.analysis.identify import IdentifyConfig, _data_quality
from vivbench.preprocess.chain import preprocess_arrays
from vivbench.io.event import event_arrays, read_event
from vivbench.synth import CampaignConfig, generate_campaign  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/_campaigns.py
from _campaigns import CLEAN  # noqa: E402

OUT = Path(__file__).resolve().parent / "out"
CAMPAIGN = OUT / "campaign"
METHODS = {
    "band-limited setting (chain default)": Derivative.for_envelope(),
    "white-noise rule": Derivative(),
    "exact TV, band noise rule": Derivative(time_scale=20.0, huber=0.0, noise_scale=10.0),
    "finite differences": Derivative(method="finite_difference"),
    "Savitzky-Golay": Derivative(method="savgol"),
}
TUNE_TIME_SCALES = (10.0, 20.0, 40.0, 80.0)
TUNE_HUBERS = (1.0, 3.0, 10.0, 30.0, 100.0)
TUNE_SECTION = 1  # mid-span


def _event_series(path: Path, config: IdentifyConfig) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[np.ndarray]]:
    """Segments (t, A) of the preprocessed event and, per segment, the true dA/dt on the shared times.

    Returns the whole segments (each is differentiated as the chain does) and,
    per segment, a tuple (mask of the times shared with the truth grid, true
    dA/dt at them, m/s).
    """
    tree = read_event(path)
    arr = event_arrays(tree)
    azimuth = float(tree.attrs["span_azimuth_deg"])
    arr, _ = _data_quality(arr, azimuth, config)
    pre = preprocess_arrays(wind_time=arr["wind_time"], u=arr["u"], v=arr["v"], accel_time=arr["accel_time"],
                            acc=arr["acc"], span_azimuth_deg=azimuth, config=config.preprocess)
    truth = tree["truth"]
    t_true = truth["time"].values
    da_true = truth["r"].values.sum(axis=-1)  # (time, section): sum of the order contributions
    segments, truths = [], []
    for seg in np.unique(pre.segment[pre.segment >= 0]):
        sel = pre.segment == seg
        t = pre.t[sel]
        if t.size < 5:
            continue
        idx = np.clip(np.searchsorted(t_true, t), 0, t_true.size - 1)
        # Both grids are integer multiples of their steps from the same start.
        shared = np.abs(t_true[idx] - t) <= 1e-6 * (t[1] - t[0])
        segments.append((t, pre.A[sel]))
        truths.append((shared, da_true[idx[shared]]))
    return segments, truths


def _rel_err(segments, truths, derivs, columns=None) -> float:
    """Relative RMS error per section over the event's shared times, RMS over the sections."""
    est = np.concatenate([d[m] for d, (m, _) in zip(derivs, truths)])
    true = np.concatenate([tr for _, tr in truths])
    if columns is not None:
        est, true = est[:, columns], true[:, columns]
    per = np.sqrt(np.mean((est - true) ** 2, axis=0) / np.mean(true**2, axis=0))
    return float(np.sqrt(np.mean(per**2)))


def _score_campaign(files: list[Path]) -> list[dict]:
    config = IdentifyConfig()
    rows = []
    for path in files:
        segments, truths = _event_series(path, config)
        if not segments:
            continue
        row = {"event": path.stem, "n_shared": int(sum(m.sum() for m, _ in truths))}
        for name, method in METHODS.items():
            t0 = time.perf_counter()
            derivs = [method.differentiate(a, t) for t, a in segments]
            row[f"time_{name}_s"] = time.perf_counter() - t0
            row[name] = _rel_err(segments, truths, derivs)
        tuned = {}
        for ts in TUNE_TIME_SCALES:
            for h in TUNE_HUBERS:
                d = Derivative(time_scale=ts, huber=h, noise_scale=ts / 2)
                derivs = [d.differentiate(a[:, TUNE_SECTION], t) for t, a in segments]
                sub = [(m, tr[:, TUNE_SECTION]) for m, tr in truths]
                est = np.concatenate([x[m] for x, (m, _) in zip(derivs, sub)])
                true = np.concatenate([tr for _, tr in sub])
                tuned[(ts, h)] = float(np.sqrt(np.mean((est - true) ** 2) / np.mean(true**2)))
        best = min(tuned, key=tuned.get)
        d = Derivative(time_scale=best[0], huber=best[1], noise_scale=best[0] / 2)
        row["tuned Huber-TV"] = _rel_err(segments, truths, [d.differentiate(a, t) for t, a in segments])
        row["tuned_setting"] = {"time_scale": best[0], "huber": best[1]}
        rows.append(row)
        print(f"  {row['event']}: " + "  ".join(f"{k} {row[k]:.3f}" for k in (*METHODS, "tuned Huber-TV")), flush=True)
    return rows


def _summary(rows: list[dict]) -> dict:
    names = (*METHODS, "tuned Huber-TV")
    out = {"n_events": len(rows)}
    for name in names:
        v = np.array([r[name] for r in rows])
        out[name] = {"median": float(np.median(v)), "geomean": float(np.exp(np.mean(np.log(v)))),
                     "max": float(v.max())}
    for name in METHODS:
        out[name]["time_total_s"] = float(sum(r[f"time_{name}_s"] for r in rows))
    new = np.array([r["band-limited setting (chain default)"] for r in rows])
    for other in ("white-noise rule", "finite differences", "Savitzky-Golay"):
        out[f"events where band-limited setting beats {other}"] = int(np.sum(new < np.array([r[other] for r in rows])))
    return out


def _print_table(title: str, summary: dict) -> None:
    print(f"\n{title}: relative RMS error of dA/dt against the truth ({summary['n_events']} events)")
    header = f"{'method':<26} {'median':>7} {'geomean':>7} {'max':>7} {'time':>8}"
    print(header)
    print("-" * len(header))
    for name in (*METHODS, "tuned Huber-TV"):
        s = summary[name]
        tm = f"{s['time_total_s']:7.2f}s" if "time_total_s" in s else f"{'-':>8}"
        print(f"{name:<26} {s['median']:7.4f} {s['geomean']:7.4f} {s['max']:7.4f} {tm}")
    for key, value in summary.items():
        if key.startswith("events where"):
            print(f"{key}: {value}/{summary['n_events']}")


def main(argv=None) -> dict:
    """Score every method on the default campaign and on a noise-free variant; print and return the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaign", default=None, help="campaign directory (default benchmarks/out/campaign)")
    parser.add_argument("--events", type=int, default=31, help="first N events (default 31)")
    parser.add_argument("--clean", type=int, default=8, help="noise-free events generated (default 8; 0: none)")
    args = parser.parse_args(argv)
    campaign, n_events, n_clean = args.campaign, args.events, args.clean
    camp = Path(campaign) if campaign is not None else CAMPAIGN
    if campaign is None and not (camp / "catalogue.csv").exists():
        subprocess.run([sys.executable, "-m", "vivbench.cli", "synth", "--out", str(camp), "--workers", "2"], check=True)
    files = sorted(camp.glob("E*.nc"))[:n_events]
    print(f"default campaign {camp}: {len(files)} events")
    rows = _score_campaign(files)
    result = {"campaign": str(camp), "default": {"summary": _summary(rows), "events": rows}}
    if n_clean > 0:
        with tempfile.TemporaryDirectory() as tmp:
            generate_campaign(CampaignConfig(n_events=n_clean, generator=CLEAN), tmp, workers=1)
            print(f"noise-free variant: {n_clean} events")
            clean_rows = _score_campaign(sorted(Path(tmp).glob("E*.nc")))
        result["noise_free"] = {"summary": _summary(clean_rows), "events": clean_rows}
    _print_table("default campaign", result["default"]["summary"])
    if n_clean > 0:
        _print_table("noise-free variant", result["noise_free"]["summary"])
    OUT.mkdir(exist_ok=True)
    (OUT / "derivative_campaign.json").write_text(json.dumps(result, indent=2, default=float) + "\n")
    return result


if __name__ == "__main__":
    main()
