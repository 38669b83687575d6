"""Benchmark: TV-regularised derivative, vivbench against pynumdiff.

Reference: ``pynumdiff.total_variation_regularization.iterative_velocity``,
Chartrand's lagged-diffusivity TVRegDiff ("small" variant, conjugate gradients
per iteration), one column at a time. Ours: ``Derivative(method="tv")``, the
interior-point solver on all three columns at once.

Signals: five envelope shapes of a bridge's VIV (modal amplitude Q(t), m),
three sections A_k = phi_k Q with phi = (0.707, 1, 0.707), n = 4800 samples at
dt = 0.25 s (20 min), independent white noise of 1 % of each column's RMS.

Fair tuning: each method gets a two-parameter grid (ours: time_scale x huber,
which includes exact TV at huber = 0; reference: gamma x iterations), the
setting with the smallest relative RMS derivative error on the mid-span column
(60 s dropped at each end) is chosen per event, then both are scored on all
three columns and timed at that setting. Note that pynumdiff smooths |Du| as
sqrt((Du)^2 + 1e-6) in absolute units, which for envelopes in metres makes its
penalty effectively quadratic; ours reaches that regime through huber > 0, so
the exact-TV (huber = 0) figures are reported separately.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import sys  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/_timing.py
from _timing import best_of  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

from vivbench.identify.derivative import Derivative  # noqa: E402

DT = 0.25  # s
N = 4800
PHI = np.array([0.707, 1.0, 0.707])
NOISE = 0.01  # of each column's RMS
EDGE = 60.0  # s dropped at each end when scoring
TUNE_COLUMN = 1
OUR_TIME_SCALES = (5.0, 10.0, 20.0, 40.0, 80.0, 160.0)
OUR_HUBERS = (0.0, 1.0, 3.0, 10.0, 30.0, 100.0)
REF_GAMMAS = tuple(np.logspace(-1, 5, 13))
REF_ITERATIONS = (1, 5)


def _events(t: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Modal envelope Q(t) (m) and its exact derivative (m/s) per event."""
    out = {}
    out["tanh step"] = (0.1 + 0.05 * np.tanh((t - 600) / 100), 0.05 / 100 / np.cosh((t - 600) / 100) ** 2)
    k, r, q0 = 0.3, 1 / 150, 0.01
    q = k / (1 + (k / q0 - 1) * np.exp(-r * t))
    out["logistic growth"] = (q, r * q * (1 - q / k))
    out["free decay"] = (0.2 * np.exp(-t / 400), -0.2 / 400 * np.exp(-t / 400))
    s1 = 1 / (1 + np.exp(-(t - 300) / 40))
    s2 = 1 / (1 + np.exp(-(t - 900) / 60))
    out["lock-in event"] = (
        0.02 + 0.23 * s1 * (1 - s2),
        0.23 * (s1 * (1 - s1) / 40 * (1 - s2) - s1 * s2 * (1 - s2) / 60),
    )
    w1, w2 = 2 * np.pi / 180, 2 * np.pi / 75
    out["wind-modulated"] = (
        0.15 + 0.03 * np.sin(w1 * t) + 0.02 * np.sin(w2 * t + 1),
        0.03 * w1 * np.cos(w1 * t) + 0.02 * w2 * np.cos(w2 * t + 1),
    )
    return out


def _rel_rms(est: np.ndarray, true: np.ndarray, inner: slice) -> float:
    """Relative RMS error over the inner samples, RMS over columns."""
    est = est.reshape(est.shape[0], -1)[inner]
    true = true.reshape(true.shape[0], -1)[inner]
    per_col = np.sqrt(np.mean((est - true) ** 2, axis=0) / np.mean(true**2, axis=0))
    return float(np.sqrt(np.mean(per_col**2)))


def _ours(x: np.ndarray, t: np.ndarray, time_scale: float, huber: float) -> np.ndarray:
    return Derivative(method="tv", time_scale=time_scale, huber=huber).differentiate(x, t)


def _reference(x: np.ndarray, gamma: float, iterations: int) -> np.ndarray:
    with warnings.catch_warnings():
        # pynumdiff warns at import that its cvxpy-based methods are absent.
        warnings.simplefilter("ignore")
        from pynumdiff.total_variation_regularization import iterative_velocity

    x2 = x.reshape(x.shape[0], -1)
    out = np.empty_like(x2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for j in range(x2.shape[1]):
            out[:, j] = iterative_velocity(x2[:, j], DT, iterations, gamma)[1]
    return out.reshape(x.shape)




def main(seed: int = 20190101, ref_repeats: int = 1, our_repeats: int = 5) -> dict:
    """Run the comparison; print a table and return the figures."""
    t = np.arange(N) * DT
    inner = slice(int(EDGE / DT), N - int(EDGE / DT))
    rng = np.random.default_rng(seed)
    rows = []
    for name, (q, dq) in _events(t).items():
        clean = q[:, None] * PHI
        truth = dq[:, None] * PHI
        x = clean + NOISE * np.sqrt(np.mean(clean**2, axis=0)) * rng.standard_normal(clean.shape)
        col = x[:, TUNE_COLUMN]
        col_truth = truth[:, TUNE_COLUMN]

        ours_grid = {
            (ts, h): _rel_rms(_ours(col, t, ts, h), col_truth, inner) for ts in OUR_TIME_SCALES for h in OUR_HUBERS
        }
        ours_best = min(ours_grid, key=ours_grid.get)
        exact_best = min((k for k in ours_grid if k[1] == 0.0), key=ours_grid.get)
        ref_grid = {(g, it): _rel_rms(_reference(col, g, it), col_truth, inner) for g in REF_GAMMAS for it in REF_ITERATIONS}
        ref_best = min(ref_grid, key=ref_grid.get)

        err_ours = _rel_rms(_ours(x, t, *ours_best), truth, inner)
        err_exact = _rel_rms(_ours(x, t, *exact_best), truth, inner)
        err_default = _rel_rms(Derivative().differentiate(x, t), truth, inner)
        err_ref = _rel_rms(_reference(x, *ref_best), truth, inner)
        err_fd = _rel_rms(np.gradient(x, DT, axis=0), truth, inner)
        t_ours, _ = best_of(lambda: _ours(x, t, *ours_best), our_repeats)
        t_exact, _ = best_of(lambda: _ours(x, t, *exact_best), our_repeats)
        t_ref, _ = best_of(lambda: _reference(x, *ref_best), ref_repeats)
        rows.append(
            {
                "event": name,
                "ours_setting": {"time_scale": ours_best[0], "huber": ours_best[1]},
                "ours_exact_tv_setting": {"time_scale": exact_best[0], "huber": 0.0},
                "ref_setting": {"gamma": float(ref_best[0]), "iterations": ref_best[1]},
                "err_ours": err_ours,
                "err_ours_exact_tv": err_exact,
                "err_ours_default": err_default,
                "err_ref": err_ref,
                "err_finite_difference": err_fd,
                "time_ours_s": t_ours,
                "time_ours_exact_tv_s": t_exact,
                "time_ref_s": t_ref,
                "error_ratio": err_ours / err_ref,
                "error_ratio_exact_tv": err_exact / err_ref,
                "speedup": t_ref / t_ours,
                "speedup_exact_tv": t_ref / t_exact,
            }
        )

    def gmean(key: str) -> float:
        return float(np.exp(np.mean([np.log(r[key]) for r in rows])))

    summary = {
        "n_samples": N,
        "n_columns": len(PHI),
        "dt_s": DT,
        "noise_fraction": NOISE,
        "geomean_error_ratio": gmean("error_ratio"),
        "geomean_error_ratio_exact_tv": gmean("error_ratio_exact_tv"),
        "geomean_speedup": gmean("speedup"),
        "geomean_speedup_exact_tv": gmean("speedup_exact_tv"),
        "events": rows,
    }

    print(f"TV derivative, {N} samples x {len(PHI)} columns, dt = {DT} s, {NOISE:.0%} noise; relative RMS error of dA/dt")
    header = f"{'event':<16} {'ours':>7} {'exactTV':>7} {'default':>7} {'pynumd':>7} {'FD':>7} | {'t ours':>8} {'t exTV':>8} {'t pynd':>8} | {'err x':>6} {'speedup':>7}"
    print(header)
    print("-" * len(header))
    for r in rows:
        print(
            f"{r['event']:<16} {r['err_ours']:7.4f} {r['err_ours_exact_tv']:7.4f} {r['err_ours_default']:7.4f} "
            f"{r['err_ref']:7.4f} {r['err_finite_difference']:7.2f} | {r['time_ours_s'] * 1e3:6.1f}ms "
            f"{r['time_ours_exact_tv_s'] * 1e3:6.1f}ms {r['time_ref_s']:7.2f}s | {r['error_ratio']:6.2f} {r['speedup']:6.0f}x"
        )
    print(
        f"geometric means: error ratio ours/pynumdiff {summary['geomean_error_ratio']:.2f} "
        f"(exact TV {summary['geomean_error_ratio_exact_tv']:.2f}), "
        f"speed-up {summary['geomean_speedup']:.0f}x (exact TV {summary['geomean_speedup_exact_tv']:.0f}x)"
    )
    for r in rows:
        print(f"  {r['event']:<16} ours {r['ours_setting']}  exact TV {r['ours_exact_tv_setting']}  pynumdiff {r['ref_setting']}")
    return summary


if __name__ == "__main__":
    main()
