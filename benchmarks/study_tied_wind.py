"""Benchmark: one curve of the sections' mean wind, or the sections' curves of one shared function (scratch fitter).

Run::

    .venv/bin/python benchmarks/study_tied_wind.py --campaign CAMP --results ID [--n-basis 15]

The averaged truth (docs/concepts.md (the truth)) sums every section's force, each a function
of that section's own felt wind: Q' = sum_j w_j g(U_j) Q + ... with one
aerodynamic function g for the whole deck. The varying model's mean wind
evaluates one curve at the weighted mean, g(sum_j w_j U_j) ("mean"); the
tied design keeps one shared curve but sums it over the sections,
sum_j w_j g(U_j) ("tied": the columns sum_j w_j B_m(U_j), as many
coefficients as "mean", a third of ``wind_input="additive"``'s). This
benchmark fits both with equal and with modal weights (each section's share
of sum_t A_k^2), on the truth's own (A, U, dA) and on the identification's
records (dA/dt by ``CAMPAIGN_DERIVATIVE``, winds smoothed by 30 s),
with a minimal penalised least-squares fitter of its own (cubic B-splines,
``n_basis`` of them between the 0.1 % and 99.9 % quantiles of the winds,
second-difference penalty chosen by 5-fold cross-validation over events,
the yaw covariate sin^2 psi to the first power, no effective-variance
weights, no bootstrap, every 4th measured sample), and scores the median
dA/dt error on the truth's (A, U) as ``study_misspecification.py`` does.

It is a feasibility check, not the varying model: its "mean" rows differ from
``VaryingCoefficientSINDy``'s. Nothing is asserted; ``python benchmarks/run_study.py tied_wind
--campaign CAMP --results ID`` writes the rows as a results page.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import study_misspecification as bm  # noqa: E402

from vivbench.models.varying import bspline_basis, difference_penalty, uniform_knots  # noqa: E402
from vivbench.models.wind_weights import modal_wind_weights  # noqa: E402
from vivbench.preprocess.wind_smoothing import smooth_wind  # noqa: E402

PENALTIES = 10.0 ** np.arange(-7.0, 1.5, 1.0)


def _stack(records, step: int) -> dict:
    """The records' samples (every ``step``-th) in one set of arrays, with each sample's event."""
    out = {k: [] for k in ("A", "U", "z", "dA", "ev")}
    for e, r in enumerate(records):
        sl = slice(None, None, step)
        out["A"].append(r.A[sl])
        out["U"].append(r.U[sl])
        out["dA"].append(r.dA[sl])
        out["z"].append(np.sin(np.radians(r.yaw[sl])) ** 2)
        out["ev"].append(np.full(r.A[sl].shape[0], e))
    return {k: np.concatenate(v) for k, v in out.items()}


def _design(d: dict, k: int, w: np.ndarray, mode: str, knots, aref: float, zref: float) -> np.ndarray:
    """Columns (A_k / aref)^i x [B(U), z B(U)], B(U) either B(sum w U) or sum w B(U); shape (n, 8 M)."""
    A = d["A"][:, k] / aref
    if mode == "mean":
        B = bspline_basis(np.nansum(d["U"] * w, 1), knots)
        cols = [B, B * (np.nansum(d["z"] * w, 1) / zref)[:, None]]
    else:
        cols = [0.0, 0.0]
        for s in range(d["U"].shape[1]):
            B = bspline_basis(d["U"][:, s], knots) * w[s]
            cols[0] = cols[0] + B
            cols[1] = cols[1] + B * (d["z"][:, s] / zref)[:, None]
    base = np.concatenate(cols, 1)
    return np.concatenate([base * (A**i)[:, None] for i in range(4)], 1)


def fit(d: dict, w: np.ndarray, mode: str, n_basis: int, folds: int = 5):
    """Knots, yaw scale and per section (coefficients, aref, penalty) of the penalised fit."""
    allU = d["U"][np.isfinite(d["U"])]
    knots = uniform_knots(np.quantile(allU, 0.001), np.quantile(allU, 0.999), n_basis)
    zref = float(np.sqrt(np.nanmean(d["z"] ** 2)))
    P = np.kron(np.eye(8), difference_penalty(n_basis))
    coefs = []
    for k in range(d["A"].shape[1]):
        aref = float(np.nanmedian(d["A"][:, k]))
        X = _design(d, k, w, mode, knots, aref, zref)
        y = d["dA"][:, k]
        ok = np.isfinite(X).all(1) & np.isfinite(y)
        X, y, fold = X[ok], y[ok], d["ev"][ok] % folds
        ys = np.std(y)
        y = y / ys
        Gf = np.stack([X[fold == f].T @ X[fold == f] for f in range(folds)])
        bf = np.stack([X[fold == f].T @ y[fold == f] for f in range(folds)])
        yf = np.array([y[fold == f] @ y[fold == f] for f in range(folds)])
        G, b = Gf.sum(0), bf.sum(0)
        sc = np.trace(G) / np.trace(P)
        ridge = 1e-10 * sc * np.eye(b.size)
        cv = []
        for lam in PENALTIES:
            err = 0.0
            for f in range(folds):
                c = np.linalg.solve(G - Gf[f] + lam * sc * P + ridge, b - bf[f])
                err += yf[f] - 2 * c @ bf[f] + c @ Gf[f] @ c
            cv.append(err)
        lam = PENALTIES[int(np.argmin(cv))]
        coefs.append((np.linalg.solve(G + lam * sc * P + ridge, b) * ys, aref, lam))
    return knots, zref, coefs


def _predict(model, d: dict, w: np.ndarray, mode: str) -> np.ndarray:
    knots, zref, coefs = model
    dd = dict(d, U=np.clip(d["U"], knots[3] + 1e-9, knots[-4] - 1e-9))  # the curves held at the knots' ends
    out = np.full(d["A"].shape, np.nan)
    for k, (c, aref, _lam) in enumerate(coefs):
        out[:, k] = _design(dd, k, w, mode, knots, aref, zref) @ c
    return out


def score(model, events, w: np.ndarray, mode: str) -> float:
    """Median over the (window, section) pairs with dynamics of the relative RMS dA/dt error on the truth's (A, U)."""
    errs = [bm.window_dA_errors(_predict(model, _stack([ev["truth_rec"]], 1), w, mode), ev) for ev in events]
    return float(np.median(np.concatenate(errs)))


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaign", required=True, type=Path)
    parser.add_argument("--results", required=True, type=Path)
    parser.add_argument("--n-basis", type=int, default=15)
    args = parser.parse_args(argv)
    measured, events = bm.load_campaign(args.campaign, args.results)
    S = measured[0].U.shape[1]
    weights = {"equal": np.full(S, 1.0 / S), "modal": modal_wind_weights(np.concatenate([r.A for r in measured]))}
    truth_step = max(1, int(round(1.0 / np.median(np.diff(events[0]["truth_rec"].t)))))
    data = {"truth": _stack([ev["truth_rec"] for ev in events], truth_step),
            "measured": _stack([smooth_wind(r, 30.0) for r in measured], 4)}
    print(f"{args.campaign}: modal weights {np.round(weights['modal'], 3)}")
    rows = []
    for wname, w in weights.items():
        for mode in ("mean", "tied"):
            for dname, d in data.items():
                model = fit(d, w, mode, args.n_basis)
                rows.append({"weights": wname, "design": mode, "data": dname,
                             "dA_error_median": score(model, events, w, mode),
                             "penalty_per_section": ", ".join(f"{c[2]:.0e}" for c in model[2])})
                print(rows[-1], flush=True)
    return {"campaign": str(args.campaign), "modal_weights": [float(x) for x in weights["modal"]], "rows": rows}


if __name__ == "__main__":
    main()
