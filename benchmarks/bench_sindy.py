"""Windowed SINDy: the fast engine against the pysindy loop a user would write.

Workload: a campaign-like set of events (default 31 events x 100 windows of
50 s at 4 Hz, 3 equations, 69 terms, 22 thresholds). The data come from a
sparse model in the library (per section: U, A, A U, A^3) integrated with
slowly varying wind, with 10 % noise on dA/dt and 0.5 % on A. To run on
another campaign (for instance the truth of ``vivbench.synth`` events: U, A on
the truth grid and a derivative of A), pass ``events=[(t, A, U, dA), ...]``
to :func:`main`.

Ours: ``EventWindowSINDy(...).fit(t, A, U, dA)`` per event, end to end (window
libraries included), on every window. Reference, on a subset of windows:
per window and threshold ``ps.SINDy(optimizer=ps.STLSQ(threshold=th, alpha=...,
max_iter=...), feature_library=ps.IdentityLibrary()).fit(Theta, t=dt,
x_dot=y)`` on the same scaled design and targets, then AICc; and the bare
optimizer ``ps.STLSQ(...).fit(Theta, y)`` as a lower bound of pysindy's cost.
The window libraries handed to pysindy are built outside its timing.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402
import pysindy as ps  # noqa: E402
from scipy.ndimage import gaussian_filter1d  # noqa: E402

from vivbench.regression import lstsq as _engine  # noqa: E402
from vivbench.regression.settings import DEFAULT_THRESHOLDS
from vivbench.regression.stlsq import aicc
from vivbench.models.window import EventWindowSINDy
from vivbench.preprocess.windows import window_bounds
from vivbench.library.basis import condition_number, window_library
from vivbench.core.terms import evaluate_library, feature_exponents

DT = 0.25


def _true_coef() -> np.ndarray:
    ex = feature_exponents(3)
    xi = np.zeros((3, 69))
    for k in range(3):
        for (i, j), value in {(0, 1): 1e-3, (1, 1): 0.02, (1, 0): -0.15, (3, 0): -0.5}.items():
            xi[k, np.flatnonzero((ex[:, 0] == k) & (ex[:, 1] == i) & (ex[:, 2] == j))[0]] = value
    return xi


def make_campaign(n_events: int = 31, windows_per_event: int = 100, seed: int = 0) -> list:
    """Events (t, A, U, dA) of the sparse model, integrated together by RK4."""
    rng = np.random.default_rng(seed)
    duration = 50.0 + 25.0 * (windows_per_event - 1)
    n = int(round(duration / DT)) + 1
    # Wind on a half-step grid for the RK4 stages: 8 m/s, slow swings, gusts.
    th = np.arange(2 * n - 1) * (DT / 2)
    phase = rng.uniform(0, 2 * np.pi, (n_events, 1, 3))
    gust = gaussian_filter1d(rng.standard_normal((n_events, th.size, 3)), sigma=10 / (DT / 2), axis=1)
    gust /= gust.std(axis=1, keepdims=True)
    Uh = 8.0 + 0.8 * np.sin(2 * np.pi * th[None, :, None] / 900.0 + phase) + 0.25 * gust
    xi = _true_coef()

    def f(a, u):
        return evaluate_library(a, u) @ xi.T

    A = np.empty((n_events, n, 3))
    A[:, 0] = rng.uniform(0.05, 0.2, (n_events, 3))
    for i in range(n - 1):
        a = A[:, i]
        u0, u1, u2 = Uh[:, 2 * i], Uh[:, 2 * i + 1], Uh[:, 2 * i + 2]
        k1 = f(a, u0)
        k2 = f(a + DT / 2 * k1, u1)
        k3 = f(a + DT / 2 * k2, u1)
        k4 = f(a + DT * k3, u2)
        A[:, i + 1] = a + DT / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    U = Uh[:, ::2]
    t = np.arange(n) * DT
    events = []
    for ev in range(n_events):
        dA = f(A[ev], U[ev])
        dA = dA + 0.1 * dA.std(axis=0) * rng.standard_normal(dA.shape)
        An = A[ev] * (1 + 0.005 * rng.standard_normal(A[ev].shape))
        events.append((t, An, U[ev], dA))
    return events


def _pysindy_window(theta, y, thresholds, *, alpha, max_iter, use_sindy, unbias=True):
    coefs = []
    for th in thresholds:
        opt = ps.STLSQ(threshold=th, alpha=alpha, max_iter=max_iter, unbias=unbias)
        if use_sindy:
            model = ps.SINDy(optimizer=opt, feature_library=ps.IdentityLibrary())
            model.fit(theta, t=DT, x_dot=y)
            coefs.append(model.coefficients())
        else:
            coefs.append(opt.fit(theta, y).coef_)
    coefs = np.stack(coefs, axis=1)  # (q, T, p)
    res = y.T[:, None, :] - np.einsum("np,qtp->qtn", theta, coefs)
    rss = np.sum(res**2, axis=2)
    k = np.count_nonzero(coefs, axis=2)
    floor = 1e-16 * np.sum(y**2, axis=0)[:, None]
    a = np.where(k > 0, aicc(rss, k, theta.shape[0], floor=floor), np.inf)
    sel = np.where(np.isfinite(a).any(axis=1), np.argmin(a, axis=1), -1)
    return coefs, sel


def main(events=None, *, n_reference: int = 100, alpha: float = 0.05, max_iter: int = 20, unbias: bool = True,
         verbose: bool = True) -> dict:
    """Run ours on all windows and pysindy on ``n_reference`` of them; return the figures."""
    if events is None:
        events = make_campaign()
    thresholds = np.asarray(DEFAULT_THRESHOLDS)
    # Regression and AICc only, like the pysindy loop: no identifiability competitors.
    est = dict(alpha=alpha, max_iter=max_iter, thresholds=thresholds, unbias=unbias)

    EventWindowSINDy(**est).fit(*events[0])  # warm-up (imports, LAPACK workspaces)
    models = []
    # Time spent in the truncated-SVD refits that pysindy's unbiased refit
    # (lstsq with a singular-value cut) forces on ill-conditioned supports:
    # one LAPACK gelsd each, the part of ours that batching cannot remove.
    svd_time = [0.0]
    plain = _engine.NestedFactors.truncated_lstsq

    def timed(self, *args, **kwargs):
        s0 = time.perf_counter()
        try:
            return plain(self, *args, **kwargs)
        finally:
            svd_time[0] += time.perf_counter() - s0

    _engine.NestedFactors.truncated_lstsq = timed
    try:
        t0 = time.perf_counter()
        for ev in events:
            models.append(EventWindowSINDy(**est).fit(*ev))
        ours_time = time.perf_counter() - t0
    finally:
        _engine.NestedFactors.truncated_lstsq = plain
    n_windows = sum(m.window_start_.size for m in models)

    # Reference subset: windows spread evenly over the campaign.
    pairs = [(e, w) for e, m in enumerate(models) for w in range(m.window_start_.size)]
    pick = np.linspace(0, len(pairs) - 1, min(n_reference, len(pairs))).round().astype(int)
    subset = [pairs[i] for i in pick]
    designs = []
    for e, w in subset:
        t, A, U, dA = events[e]
        first, stop = window_bounds(t, 50.0, 25.0)[2:]
        sl = slice(first[w], stop[w])
        lib = window_library(A[sl], U[sl])
        designs.append((lib.theta, dA[sl] / models[e].y_scale_[w]))

    timings = {}
    results = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for use_sindy in (True, False):
            name = "pysindy SINDy loop" if use_sindy else "pysindy STLSQ loop"
            t0 = time.perf_counter()
            results[name] = [
                _pysindy_window(th_, y_, thresholds, alpha=alpha, max_iter=max_iter, use_sindy=use_sindy, unbias=unbias)
                for th_, y_ in designs
            ]
            timings[name] = (time.perf_counter() - t0) / len(designs)

    ref_coefs = [r[0] for r in results["pysindy SINDy loop"]]
    ref_sel = [r[1] for r in results["pysindy SINDy loop"]]
    sel_agree = path_agree = n_sel = n_path = 0
    coef_err = []
    for (e, w), (theta, y), coefs, sel in zip(subset, designs, ref_coefs, ref_sel):
        m = models[e]
        path_agree += np.sum(np.all((coefs != 0) == m.path_support_[w], axis=2))
        n_path += coefs.shape[0] * coefs.shape[1]
        for q in range(3):
            n_sel += 1
            ours = m.support_[w, q]
            if sel[q] == m.selected_[w, q] and np.array_equal(ours, coefs[q, sel[q]] != 0):
                sel_agree += 1
                if condition_number(theta[:, ours]) < 1e5:
                    c_ref = coefs[q, sel[q]]
                    coef_err.append(np.max(np.abs(m.coef_scaled_[w, q] - c_ref)) / np.max(np.abs(c_ref)))

    ours_per_window = ours_time / n_windows
    figures = {
        "n_events": len(events),
        "unbias": unbias,
        "n_windows": n_windows,
        "n_thresholds": int(thresholds.size),
        "ours_total_s": ours_time,
        "ours_ms_per_window": 1e3 * ours_per_window,
        "ours_windows_per_s": 1.0 / ours_per_window,
        "n_reference_windows": len(subset),
        "pysindy_sindy_ms_per_window": 1e3 * timings["pysindy SINDy loop"],
        "pysindy_stlsq_ms_per_window": 1e3 * timings["pysindy STLSQ loop"],
        "speedup_vs_sindy_loop": timings["pysindy SINDy loop"] / ours_per_window,
        "speedup_vs_stlsq_loop": timings["pysindy STLSQ loop"] / ours_per_window,
        "selected_support_agreement": sel_agree / n_sel,
        "path_support_agreement": float(path_agree / n_path),
        "coef_max_rel_diff_well_conditioned": float(max(coef_err)) if coef_err else float("nan"),
        "n_coef_compared": len(coef_err),
        "ours_solves": {k: int(sum(m.solves_[k] for m in models)) for k in models[0].solves_},
        "ours_truncated_svd_s": svd_time[0],
        "ours_truncated_svd_share": svd_time[0] / ours_time,
        # The ratio ours would reach if everything but those refits were free.
        "speedup_ceiling_from_svd_refits": (
            timings["pysindy SINDy loop"] * n_windows / svd_time[0] if svd_time[0] > 0 else float("inf")
        ),
    }
    if verbose:
        print(
            f"workload: {len(events)} events, {n_windows} windows x 3 equations x 69 terms "
            f"x {thresholds.size} thresholds"
        )
        print(f"{'method':<24}{'windows':>9}{'ms/window':>12}{'windows/s':>12}{'ratio':>9}")
        ms = 1e3 * ours_per_window
        print(f"{'ours (EventWindowSINDy)':<24}{n_windows:>9}{ms:>12.2f}{1 / ours_per_window:>12.1f}{1.0:>9.1f}")
        for name in ("pysindy SINDy loop", "pysindy STLSQ loop"):
            tw = timings[name]
            print(f"{name:<24}{len(subset):>9}{1e3 * tw:>12.1f}{1 / tw:>12.2f}{tw / ours_per_window:>9.1f}")
        print(
            f"agreement on {len(subset)} windows: selected supports {sel_agree}/{n_sel} "
            f"({100 * sel_agree / n_sel:.1f} %), path supports {100 * path_agree / n_path:.2f} %, "
            f"max rel. coef. diff {figures['coef_max_rel_diff_well_conditioned']:.1e} "
            f"({len(coef_err)} well-conditioned selected models)"
        )
        n_svd = figures["ours_solves"].get("svd", 0)
        print(
            f"truncated-SVD refits: {n_svd} ({n_svd / n_windows:.1f} per window), {svd_time[0]:.2f} s = "
            f"{100 * figures['ours_truncated_svd_share']:.0f} % of ours; with everything else free the ratio "
            f"to the SINDy loop would be at most {figures['speedup_ceiling_from_svd_refits']:.0f}"
        )
    return figures


def events_from_results(results_dir) -> list:
    """(t, A, U, dA) of the first segment of every ``*.identify.nc`` in a folder: a campaign's own windows."""
    from pathlib import Path

    import xarray as xr

    from vivbench.io.netcdf import NETCDF_ENGINE

    events = []
    for path in sorted(Path(results_dir).glob("*.identify.nc")):
        with xr.open_dataset(path, engine=NETCDF_ENGINE) as res:
            keep = res["segment"].values == 0
            events.append(tuple(res[name].values[keep] for name in ("time", "A", "U", "dA")))
    return events


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", default=None,
                        help="identification results (e.g. demo/identify): run on that campaign's windows "
                             "instead of the synthetic sparse-model workload")
    parser.add_argument("--no-unbias", action="store_true",
                        help="both sides without pysindy's unbiased refit (STLSQ(unbias=False)): the ridge "
                             "coefficients are kept, so no truncated-SVD refit is needed")
    args = parser.parse_args()
    main(events_from_results(args.results) if args.results else None, unbias=not args.no_unbias)
