"""The varying model's fast numerics against the straightforward ones they replaced (issue 11, speed).

Run: ``.venv/bin/python benchmarks/bench_varying_speed.py [--samples 60000] [--json OUT]``.

On synthetic inputs shaped like the additive model on the default campaign (3 sections' winds as
inputs, the yaw covariate, M = 10 B-splines: p = 240 columns, 1200-sample blocks), one core, best of 3:

- B-splines: :func:`vivbench.models.varying.bspline_local` against scipy's ``BSpline.design_matrix``
  (dense, as the model built it before), and their largest difference (0 expected: same recursion);
- block statistics: the grouped local products (``block_stats``) against the dense design per block
  and X_b^T X_b (what it did before), and the largest relative difference of the Grams;
- the default model's shape (one mean wind, yaw of degree 2, M = 15: p = 180): the moments of
  :func:`vivbench.models.varying_stats.block_statistics` summed by fold (what the basis choice needs)
  against ``block_stats`` summed by fold, the closed-form uniform cubic B-splines against the
  recursion, and their largest relative differences;
- the tied sum of every section's wind (``wind_input="sum"``; five sections whose winds differ by a
  smooth offset and a 4 % turbulence, yaw of degree 1, M = 14: p = 112):
  :func:`vivbench.models.varying_stats.tied_statistics` summed by fold against the untied Grams of
  ``block_stats`` (p = 560) contracted by the weights' tying (what the fit did before), and their largest
  relative difference.

Whole ``vivbench pool`` runs (wall, CPU, peak memory) are in the closing note of the branch; this
benchmark measures the kernels only. It asserts nothing.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from _timing import best_of  # noqa: E402


def _inputs(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    from vivbench.models.varying import uniform_knots

    knots = uniform_knots(4.0, 14.0, 10)
    # slowly varying winds (a smoothed anemometer at 4 Hz), amplitudes, yaw covariate, 1200-sample blocks
    U = np.clip(9.0 + np.cumsum(rng.normal(0.0, 0.02, (n, 3)), axis=0), 4.0, 14.0)
    A = rng.uniform(0.0, 0.3, n)
    z = rng.uniform(0.0, 2.0, (n, 3))
    y = rng.normal(size=n)
    block = np.arange(n) // 1200
    return knots, U, A, z, y, block


def main(samples: int = 60_000) -> dict:
    from scipy.interpolate import BSpline

    from vivbench.library.splines import bspline_basis
    from vivbench.models import varying_design as vd

    knots, U, A, z, y, block = _inputs(samples)
    nb = int(block.max()) + 1
    out = {"samples": samples, "p": 240}

    x = np.clip(U[:, 0], knots[3], knots[-4])
    t_old, B_old = best_of(lambda: BSpline.design_matrix(x, knots, 3).toarray())
    t_new, B_new = best_of(lambda: bspline_basis(x, knots))
    out["bspline"] = {"scipy_s": t_old, "local_s": t_new, "max_abs_diff": float(np.abs(B_old - B_new).max())}

    def dense():
        G = np.empty((nb, 240, 240))
        for j in range(nb):
            r = block == j
            X = vd.spline_design(U[r], A[r], knots, 0.1, z[r], 1)
            G[j] = X.T @ X
        return G

    t_old, G_old = best_of(dense)
    t_new, (G_new, *_rest) = best_of(lambda: vd.block_stats(U, A, y, block, nb, knots, 0.1, z, 1))
    out["block_stats"] = {"dense_s": t_old, "grouped_s": t_new,
                          "max_rel_diff": float(np.abs(G_new - G_old).max() / np.abs(G_old).max())}

    # The default model's shape: one wind input (the sections' weighted mean), yaw of degree 2, M = 15.
    from vivbench.library.splines import bspline_local_t, uniform_cubic_local_t
    from vivbench.models.varying import uniform_knots
    from vivbench.models.varying_stats import block_statistics, one_hot

    knots15 = uniform_knots(4.0, 14.0, 15)
    u, z1 = U[:, 0], z[:, 0]
    t_old, (f_old, v_old) = best_of(lambda: bspline_local_t(u, knots15))
    t_new, (f_new, v_new) = best_of(lambda: uniform_cubic_local_t(u, knots15))
    out["uniform_cubic"] = {"recursion_s": t_old, "closed_form_s": t_new, "same_first": bool((f_old == f_new).all()),
                            "max_abs_diff": float(np.abs(v_old - v_new).max())}
    fold = np.arange(nb) % 5

    def grouped_by_fold():
        G, b, _yy, _n = vd.block_stats(u, A, y, block, nb, knots15, 0.1, z1, 2)
        return np.stack([G[fold == f].sum(axis=0) for f in range(5)])

    def moments_by_fold():
        return block_statistics(u, A, y, block, nb, knots15, 0.1, z1, 2).sums(one_hot(fold, 5))[0]

    t_old, G_old = best_of(grouped_by_fold)
    t_new, G_new = best_of(moments_by_fold)
    out["block_statistics_one_input"] = {"p": int(G_new.shape[-1]), "grouped_by_fold_s": t_old,
                                         "moments_by_fold_s": t_new,
                                         "max_rel_diff": float(np.abs(G_new - G_old).max() / np.abs(G_old).max())}

    # The tied sum: one curve shape for the three sections' winds, weighted by the sections' weights.
    from vivbench.models.varying_stats import tied_statistics

    rng = np.random.default_rng(1)
    S, M = 5, 14
    U5 = (U[:, :1] + np.linspace(-0.8, 0.8, S) * np.sin(np.arange(samples) / 3000.0)[:, None]
          + rng.normal(0.0, 0.4, (samples, S)))
    z5 = rng.uniform(0.0, 2.0, (samples, S))
    knots14 = uniform_knots(float(U5.min()), float(U5.max()), M)
    w = np.array([0.1, 0.2, 0.4, 0.2, 0.1])
    T = vd.untie(np.eye(4 * 2 * M), w, 1, M).T  # (560 untied, 112 tied)

    def untied_contracted():
        G, b, _yy, _n = vd.block_stats(U5, A, y, block, nb, knots14, 0.1, z5, 1)
        Gf = np.stack([G[fold == f].sum(axis=0) for f in range(5)])
        return T.T @ Gf @ T

    def tied_by_fold():
        return tied_statistics(U5, A, y, block, nb, knots14, 0.1, w, z5, 1).sums(one_hot(fold, 5))[0]

    t_old, G_old = best_of(untied_contracted)
    t_new, G_new = best_of(tied_by_fold)
    out["tied_statistics"] = {"p": int(G_new.shape[-1]), "untied_contracted_s": t_old, "tied_moments_s": t_new,
                              "max_rel_diff": float(np.abs(G_new - G_old).max() / np.abs(G_old).max())}
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=60_000)
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    res = main(a.samples)
    print(json.dumps(res, indent=2))
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=2) + "\n")
