"""Benchmark: density-peaks clustering, ours against pydpc, on 3000 points in 207 dimensions.

Synthetic data of the size of the window-model features (207 = 3 sections x 69
terms): 4 Gaussian blobs of 750 points. Both run the Gaussian kernel (pydpc has
no cutoff kernel) with the same neighbour fraction; pydpc's centres are chosen
by thresholds that keep its 4 largest-delta points. Ours is also run with the
paper's cutoff kernel and automatic centres. Reported: wall times, ratio, and
the adjusted Rand index (ARI) against pydpc and against the truth.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import sys  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/_timing.py
from _timing import best_of  # noqa: E402

import numpy as np  # noqa: E402
from sklearn.metrics import adjusted_rand_score  # noqa: E402

from vivbench.identify.clustering import DensityPeaks  # noqa: E402

N_PER, K, DIM, SEP, FRACTION = 750, 4, 207, 30.0, 0.02


def _blobs(seed: int = 0):
    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(K, DIM))
    centres *= SEP / np.linalg.norm(centres, axis=1, keepdims=True)
    X = np.concatenate([c + rng.normal(size=(N_PER, DIM)) for c in centres])
    return X, np.repeat(np.arange(K), N_PER)




def main() -> dict:
    import pydpc

    X, truth = _blobs()

    def run_ref():
        clu = pydpc.Cluster(X, fraction=FRACTION, autoplot=False)
        clu.assign(min_density=0.0, min_delta=np.sort(clu.delta)[-K - 1] * (1 + 1e-12))
        return clu

    t_ref, ref = best_of(run_ref)
    t_ours, ours = best_of(lambda: DensityPeaks(kernel="gaussian", neighbor_fraction=FRACTION, n_centers=K).fit(X))
    t_auto, auto = best_of(lambda: DensityPeaks(kernel="cutoff", neighbor_fraction=FRACTION).fit(X))

    same_centres = bool(np.array_equal(np.sort(ours.centers_), np.sort(ref.clusters)))
    res = {
        "n_points": int(X.shape[0]),
        "dim": DIM,
        "t_pydpc_s": t_ref,
        "t_ours_gaussian_s": t_ours,
        "t_ours_cutoff_auto_s": t_auto,
        "ratio_ours_over_pydpc": t_ours / t_ref,
        "same_centres_as_pydpc": same_centres,
        "ari_ours_vs_pydpc": float(adjusted_rand_score(ref.membership, ours.labels_)),
        "ari_pydpc_vs_truth": float(adjusted_rand_score(truth, ref.membership)),
        "ari_ours_vs_truth": float(adjusted_rand_score(truth, ours.labels_)),
        "ari_auto_cutoff_vs_truth": float(adjusted_rand_score(truth, auto.labels_)),
        "n_auto_centres": int(auto.centers_.size),
        "max_rel_rho_diff": float(np.max(np.abs(ours.rho_ - ref.density) / ref.density)),
    }
    print(f"density peaks, {res['n_points']} points x {DIM} dims, {K} blobs, single-threaded BLAS")
    print(f"{'run':<28}{'time [s]':>10}{'ARI truth':>11}")
    print(f"{'pydpc (gaussian)':<28}{t_ref:>10.3f}{res['ari_pydpc_vs_truth']:>11.4f}")
    print(f"{'ours (gaussian, k=4)':<28}{t_ours:>10.3f}{res['ari_ours_vs_truth']:>11.4f}")
    print(f"{'ours (cutoff, automatic)':<28}{t_auto:>10.3f}{res['ari_auto_cutoff_vs_truth']:>11.4f}")
    print(f"ratio ours/pydpc {res['ratio_ours_over_pydpc']:.2f}; ARI ours vs pydpc {res['ari_ours_vs_pydpc']:.4f}; "
          f"same centres {same_centres}; automatic centres {res['n_auto_centres']}; max rel rho diff {res['max_rel_rho_diff']:.1e}")
    return res


if __name__ == "__main__":
    main()
