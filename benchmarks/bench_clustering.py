"""Benchmark: density-peaks clustering, ours against pydpc, on every window model of the default campaign.

Run: ``.venv/bin/python benchmarks/bench_clustering.py``. The default campaign
(31 events, seed 0) and its identification results are cached in
``benchmarks/out/campaign`` and ``benchmarks/out/identify`` (gitignored); when
missing they are made with the command line::

    python -m vivbench.cli synth --out benchmarks/out/campaign --workers 2
    python -m vivbench.cli identify benchmarks/out/campaign --out benchmarks/out/identify --workers 2

1. Campaign windows: every (window, equation) model of the 31 events (8685
   points) with both feature sets of :mod:`vivbench.analysis.interpret`
   ("coef": 69 standardised coefficients; "order": 4 order shares). Ours and
   pydpc run the same Gaussian kernel with the same d_c (fraction 0.02) on
   the same points. pydpc chooses centres by thresholds on (rho, delta); it is
   given the thresholds that just admit our automatic centres (min_delta and
   min_density slightly below the smallest values among them), so the two
   labelings can be compared: ARI between them, and the share of identical
   labels when ours is run with pydpc's centres. Our default (cutoff kernel,
   automatic centres) is also run, and every partition is scored against the
   true window regimes (ARI, purity).
2. Synthetic blobs of the same width as the three-equation feature vectors
   (3000 points x 207 dimensions, 4 blobs), as before.

Nothing is asserted; the figures are printed and returned.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/_timing.py
from _timing import best_of  # noqa: E402

import numpy as np  # noqa: E402
from sklearn.metrics import adjusted_rand_score  # noqa: E402

from vivbench.analysis.interpret import campaign_windows, cluster_scores
from vivbench.analysis.clustering import DensityPeaks

OUT = Path(__file__).resolve().parent / "out"
CAMPAIGN, RESULTS = OUT / "campaign", OUT / "identify"
N_PER, K, DIM, SEP, FRACTION = 750, 4, 207, 30.0, 0.02


def _blobs(seed: int = 0):
    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(K, DIM))
    centres *= SEP / np.linalg.norm(centres, axis=1, keepdims=True)
    X = np.concatenate([c + rng.normal(size=(N_PER, DIM)) for c in centres])
    return X, np.repeat(np.arange(K), N_PER)


def _ensure_campaign() -> list[Path]:
    py = sys.executable
    if not (CAMPAIGN / "catalogue.csv").exists():
        subprocess.run([py, "-m", "vivbench.cli", "synth", "--out", str(CAMPAIGN), "--workers", "2"], check=True)
    if len(list(RESULTS.glob("*.identify.nc"))) < len(list(CAMPAIGN.glob("E*.nc"))):
        subprocess.run([py, "-m", "vivbench.cli", "identify", str(CAMPAIGN), "--out", str(RESULTS), "--workers", "2"],
                       check=True)
    return sorted(RESULTS.glob("*.identify.nc"))


def _same_labels_share(ours_labels, ours_centers, ref_membership, ref_centers) -> float:
    """Share of points with the same cluster, clusters matched through their (common) centres."""
    mapping = {int(ours_labels[c]): int(ref_membership[c]) for c in ref_centers}
    mapped = np.array([mapping.get(int(lab), -1) for lab in ours_labels])
    return float(np.mean(mapped == ref_membership))


def _campaign_part(windows) -> dict:
    import pydpc

    out = {"n_points": windows.n_points}
    for name in ("coef", "order"):
        X = windows.features[name]
        t_ours, ours = best_of(lambda: DensityPeaks(kernel="gaussian", neighbor_fraction=FRACTION).fit(X), repeats=1)
        t_ref, ref = best_of(lambda: pydpc.Cluster(X, fraction=FRACTION, autoplot=False), repeats=1)
        c = ours.centers_
        top = int(ours.order_[0])
        rest = c[c != top]
        # thresholds that just admit our centres (pydpc takes > on both); the
        # densest point's delta differs by convention, so it is left out of min_delta
        min_delta = float(ref.delta[rest].min() if rest.size else ref.delta[top]) * (1 - 1e-9)
        ref.assign(min_density=float(ref.density[c].min()) * (1 - 1e-9), min_delta=min_delta)
        ref_centers = np.asarray(ref.clusters)
        given = np.union1d(ref_centers, [top])
        with_ref_centres = DensityPeaks(kernel="gaussian", neighbor_fraction=FRACTION, centers=given).fit(X)
        auto = DensityPeaks(kernel="cutoff", neighbor_fraction=FRACTION).fit(X)
        res = {
            "t_ours_gaussian_s": t_ours, "t_pydpc_s": t_ref, "ratio_ours_over_pydpc": t_ours / t_ref,
            "same_dc": bool(np.isclose(ours.dc_, ref.kernel_size, rtol=1e-12)),
            "max_rho_diff_over_max_rho": float(np.max(np.abs(ours.rho_ - ref.density)) / np.max(ref.density)),
            "n_centres_ours_gaussian_auto": int(c.size), "n_centres_pydpc_thresholds": int(ref_centers.size),
            "ari_ours_auto_vs_pydpc": float(adjusted_rand_score(ref.membership, ours.labels_)),
            "same_label_share_same_centres": _same_labels_share(with_ref_centres.labels_, given, ref.membership,
                                                                ref_centers) if top in ref_centers else float("nan"),
            "n_clusters_default": int(auto.centers_.size),
            **{f"{k}_default": v for k, v in cluster_scores(auto.labels_, windows.truth_regime).items() if k != "n_scored"},
            **{f"{k}_gaussian": v for k, v in cluster_scores(ours.labels_, windows.truth_regime).items() if k != "n_scored"},
            "cluster_sizes_default": np.bincount(auto.labels_).tolist()[:10],
        }
        for k in (2, 4):
            forced = DensityPeaks(kernel="cutoff", neighbor_fraction=FRACTION, n_centers=k).fit(X)
            res[f"ari_default_{k}_centres"] = cluster_scores(forced.labels_, windows.truth_regime)["ari"]
        out[name] = res
    return out


def _blob_part() -> dict:
    import pydpc

    X, truth = _blobs()

    def run_ref():
        clu = pydpc.Cluster(X, fraction=FRACTION, autoplot=False)
        clu.assign(min_density=0.0, min_delta=np.sort(clu.delta)[-K - 1] * (1 + 1e-12))
        return clu

    t_ref, ref = best_of(run_ref)
    t_ours, ours = best_of(lambda: DensityPeaks(kernel="gaussian", neighbor_fraction=FRACTION, n_centers=K).fit(X))
    auto = DensityPeaks(kernel="cutoff", neighbor_fraction=FRACTION).fit(X)
    return {
        "n_points": int(X.shape[0]), "dim": DIM, "t_pydpc_s": t_ref, "t_ours_gaussian_s": t_ours,
        "ratio_ours_over_pydpc": t_ours / t_ref,
        "same_centres_as_pydpc": bool(np.array_equal(np.sort(ours.centers_), np.sort(ref.clusters))),
        "ari_ours_vs_pydpc": float(adjusted_rand_score(ref.membership, ours.labels_)),
        "ari_ours_vs_truth": float(adjusted_rand_score(truth, ours.labels_)),
        "ari_auto_cutoff_vs_truth": float(adjusted_rand_score(truth, auto.labels_)),
        "n_auto_centres": int(auto.centers_.size),
    }


def main(blobs_only: bool = False) -> dict:
    """Both parts (``blobs_only``: the synthetic blobs alone, no campaign to make); print and return the figures."""
    if blobs_only:
        blobs = _blob_part()
        print(f"blobs {blobs['n_points']} x {DIM}: ours {blobs['t_ours_gaussian_s']:.3f} s, pydpc "
              f"{blobs['t_pydpc_s']:.3f} s, ratio {blobs['ratio_ours_over_pydpc']:.2f}")
        return {"blobs": blobs}
    files = _ensure_campaign()
    t0 = time.perf_counter()
    windows = campaign_windows(files, CAMPAIGN)
    t_collect = time.perf_counter() - t0
    camp = _campaign_part(windows)
    camp["t_collect_s"] = t_collect
    blobs = _blob_part()
    print(f"default campaign: {len(files)} events, {windows.n_points} window models (collected in {t_collect:.1f} s); "
          f"Gaussian kernel, d_c fraction {FRACTION}, single-threaded BLAS")
    for name in ("coef", "order"):
        r = camp[name]
        print(f"  [{name}] ours {r['t_ours_gaussian_s']:.2f} s, pydpc {r['t_pydpc_s']:.2f} s, ratio "
              f"{r['ratio_ours_over_pydpc']:.2f}; same d_c {r['same_dc']}, max |rho diff| / max rho {r['max_rho_diff_over_max_rho']:.1e}")
        print(f"         centres: ours (automatic) {r['n_centres_ours_gaussian_auto']}, pydpc with the admitting "
              f"thresholds {r['n_centres_pydpc_thresholds']}; ARI ours vs pydpc {r['ari_ours_auto_vs_pydpc']:.4f}; "
              f"identical labels with the same centres {r['same_label_share_same_centres']:.4f}")
        print(f"         default (cutoff, automatic): {r['n_clusters_default']} clusters, sizes "
              f"{r['cluster_sizes_default']}, ARI vs truth {r['ari_default']:.3f}, purity {r['purity_default']:.3f}; "
              f"Gaussian automatic ARI {r['ari_gaussian']:.3f}; forced 2 / 4 centres ARI "
              f"{r['ari_default_2_centres']:.3f} / {r['ari_default_4_centres']:.3f}")
    print(f"blobs {blobs['n_points']} x {DIM}: ours {blobs['t_ours_gaussian_s']:.3f} s, pydpc {blobs['t_pydpc_s']:.3f} s, "
          f"ratio {blobs['ratio_ours_over_pydpc']:.2f}; same centres {blobs['same_centres_as_pydpc']}, ARI vs pydpc "
          f"{blobs['ari_ours_vs_pydpc']:.4f}; automatic cutoff: {blobs['n_auto_centres']} centres, ARI vs truth "
          f"{blobs['ari_auto_cutoff_vs_truth']:.4f}")
    return {"campaign": camp, "blobs": blobs}


if __name__ == "__main__":
    main()
