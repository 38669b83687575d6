"""Density-peaks clustering: agreement with pydpc, brute-force definitions, invariances, features."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.helpers import assert_close
from vivbench.analysis.clustering import DensityPeaks, coefficient_features, decision_graph, order_features


def _blobs(seed: int, n_per: int = 50, k: int = 4, dim: int = 5, sep: float = 8.0, spread: float = 1.0):
    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(k, dim))
    centres *= sep / np.linalg.norm(centres, axis=1, keepdims=True)  # every centre at distance sep from 0
    X = np.concatenate([c + spread * rng.normal(size=(n_per, dim)) for c in centres])
    return X, np.repeat(np.arange(k), n_per)


def _same_partition(a, b) -> bool:
    a = np.asarray(a)
    b = np.asarray(b)
    pairs = set(zip(a.tolist(), b.tolist()))
    return len(pairs) == len(set(a.tolist())) == len(set(b.tolist()))


def _brute(X, dc, kernel):
    n = X.shape[0]
    D = np.sqrt(((X[:, None, :] - X[None, :, :]) ** 2).sum(-1))
    off = ~np.eye(n, dtype=bool)
    if kernel == "cutoff":
        rho = ((D < dc) & off).sum(1).astype(float)
    else:
        rho = (np.exp(-((D / dc) ** 2)) * off).sum(1)
    return D, rho


def test_matches_pydpc_gaussian():
    """pydpc has only the Gaussian kernel: compare d_c, rho, delta, labels and halo with the same centres."""
    import pydpc  # the reference implementation; installed by the test extra
    X, _ = _blobs(3, n_per=60, k=3, dim=4, sep=3.0)  # overlapping clusters, so the halo is not empty
    ref = pydpc.Cluster(X, fraction=0.03, autoplot=False)
    ours = DensityPeaks(kernel="gaussian", neighbor_fraction=0.03).fit(X)
    assert_close(ours.dc_, ref.kernel_size, what="d_c")
    assert_close(ours.rho_, ref.density, rtol=1e-9, atol=1e-10, reason="different summation order of the Gaussian terms", what="rho")
    top = ours.order_[0]
    assert top == ref.order[0], "densest point differs from pydpc's"
    rest = np.arange(X.shape[0]) != top
    # the densest point's delta is defined differently (paper: max distance; pydpc: max of other deltas)
    assert_close(ours.delta_[rest], ref.delta[rest], what="delta of the non-densest points")
    assert np.array_equal(ours.nearest_denser_[rest], ref.neighbour[rest]), "nearest denser neighbours differ"
    assert_close(ours.delta_[top], np.linalg.norm(X - X[top], axis=1).max(), rtol=1e-12)

    # pydpc's centre thresholds: the three largest-delta points (densest included by construction)
    min_delta = np.sort(ref.delta)[-4] + 1e-9
    ref.assign(min_density=0.0, min_delta=min_delta)
    assert ref.nclusters == 3, f"threshold choice gave {ref.nclusters} pydpc clusters"
    fitted = DensityPeaks(kernel="gaussian", neighbor_fraction=0.03, centers=ref.clusters).fit(X)
    # pydpc numbers centres by index, ours by density: map through the centres
    mapping = np.empty(3, dtype=int)
    mapping[fitted.labels_[ref.clusters]] = np.arange(3)
    assert np.array_equal(mapping[fitted.labels_], ref.membership), "labels differ from pydpc's with the same centres"
    assert fitted.halo_.any(), "test data should produce a non-empty halo"
    assert np.array_equal(np.flatnonzero(fitted.halo_), np.sort(ref.halo_idx)), "halo differs from pydpc's"


@pytest.mark.parametrize("kernel", ["cutoff", "gaussian"])
def test_definitions_brute_force(kernel):
    X, _ = _blobs(5, n_per=20, k=3, dim=3, sep=4.0)
    m = DensityPeaks(kernel=kernel, neighbor_fraction=0.05).fit(X)
    D, rho = _brute(X, m.dc_, kernel)
    assert_close(m.rho_, rho, rtol=1e-12, atol=1e-12, reason="sum order", what="rho")
    iu = np.triu_indices(X.shape[0], 1)
    assert_close(np.mean(D[iu] < m.dc_), 0.05, atol=1.0 / iu[0].size, reason="quantile index rounding", what="neighbour fraction")
    rank = np.empty(X.shape[0], dtype=int)
    rank[m.order_] = np.arange(X.shape[0])
    assert np.all(np.diff(m.rho_[m.order_]) <= 0), "order_ is not by decreasing density"
    for i in range(X.shape[0]):
        denser = rank < rank[i]
        if not denser.any():
            assert m.nearest_denser_[i] == -1
            assert_close(m.delta_[i], D[i].max(), what="delta of the densest point")
            continue
        assert_close(m.delta_[i], D[i, denser].min(), what=f"delta[{i}]")
        assert denser[m.nearest_denser_[i]], f"nearest denser of {i} is not denser"
    assert_close(m.gamma_, m.rho_ * m.delta_, what="gamma")
    # every point shares its label with its nearest denser neighbour, and centres carry 0..k-1 by density
    nonc = np.setdiff1d(np.arange(X.shape[0]), m.centers_)
    assert np.array_equal(m.labels_[nonc], m.labels_[m.nearest_denser_[nonc]]), "assignment rule broken"
    assert np.array_equal(m.labels_[m.centers_], np.arange(m.centers_.size)), "centre labels not 0..k-1"
    assert np.all(np.diff(rank[m.centers_]) > 0), "centres not in order of decreasing density"


@pytest.mark.parametrize("kernel", ["cutoff", "gaussian"])
def test_blobs_recovered_automatically(kernel):
    X, truth = _blobs(11, n_per=50, k=4, dim=5, sep=8.0)
    m = DensityPeaks(kernel=kernel).fit(X)
    assert m.centers_.size == 4, f"found {m.centers_.size} centres, expected 4"
    assert _same_partition(m.labels_, truth), "blobs not recovered exactly"
    assert not m.halo_.any(), "well-separated blobs have no border, hence no halo"


def test_permutation_and_scaling_invariance():
    X, _ = _blobs(7, n_per=40, k=3, dim=4, sep=4.0)  # touching clusters: assignment is non-trivial
    base = DensityPeaks().fit(X)
    perm = np.random.default_rng(1).permutation(X.shape[0])
    permuted = DensityPeaks().fit(X[perm])
    assert np.array_equal(permuted.labels_, base.labels_[perm]), "labels depend on the order of the points"
    assert np.array_equal(permuted.halo_, base.halo_[perm]), "halo depends on the order of the points"
    scaled = DensityPeaks().fit(37.0 * X)
    assert np.array_equal(scaled.labels_, base.labels_), "labels change under a common scaling"
    assert_close(scaled.dc_, 37.0 * base.dc_, rtol=1e-12, reason="round-off of scaled distances", what="d_c scales")


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), k=st.integers(1, 4), kernel=st.sampled_from(["cutoff", "gaussian"]))
def test_permutation_invariance_property(seed, k, kernel):
    X, _ = _blobs(seed, n_per=15, k=k, dim=3, sep=3.0)
    perm = np.random.default_rng(seed + 1).permutation(X.shape[0])
    a = DensityPeaks(kernel=kernel).fit(X)
    b = DensityPeaks(kernel=kernel).fit(X[perm])
    assert np.array_equal(b.labels_, a.labels_[perm]), "partition depends on the order of the points"
    assert np.array_equal(perm[b.centers_], a.centers_), "centres depend on the order of the points"


def test_n_centers_and_validation():
    X, _ = _blobs(2, n_per=30, k=3, dim=3, sep=6.0)
    m = DensityPeaks(n_centers=5).fit(X)
    assert m.centers_.size == 5 and set(m.labels_.tolist()) == set(range(5))
    assert m.centers_[0] == m.order_[0], "the densest point must be the first centre"
    not_densest = [i for i in range(3) if i != m.order_[0]]
    with pytest.raises(ValueError, match="densest"):
        DensityPeaks(centers=not_densest).fit(X)
    with pytest.raises(ValueError, match="kernel"):
        DensityPeaks(kernel="box").fit(X)
    with pytest.raises(ValueError, match="neighbor_fraction"):
        DensityPeaks(neighbor_fraction=1.5).fit(X)


def test_decision_graph_deterministic(tmp_path):
    X, _ = _blobs(4, n_per=20, k=2, dim=2)
    m = DensityPeaks().fit(X)
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    decision_graph(m.rho_, m.delta_, m.centers_, a)
    decision_graph(m.rho_, m.delta_, m.centers_, b)
    assert a.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    assert a.read_bytes() == b.read_bytes(), "decision graph output is not deterministic"


def test_feature_helpers():
    rng = np.random.default_rng(0)
    coef = rng.normal(size=(30, 3, 69))
    coef[:, 1, 5] = 2.5  # constant across windows: dropped
    feats, keep = coefficient_features(coef, return_mask=True)
    assert feats.shape == (30, 206) and keep.sum() == 206 and not keep[69 + 5]
    assert_close(feats.mean(0), 0.0, atol=1e-12, reason="round-off", what="feature means")
    assert_close(feats.std(0), 1.0, rtol=1e-12, reason="round-off", what="feature std")
    assert_close(feats[:, 0], (coef[:, 0, 0] - coef[:, 0, 0].mean()) / coef[:, 0, 0].std(), rtol=1e-12, reason="round-off")

    rms = np.abs(rng.normal(size=(10, 3, 4)))
    rms[3] = 0.0
    shares = order_features(rms)
    assert shares.shape == (10, 12)
    ok = np.arange(10) != 3
    assert_close(shares[ok].sum(1), 1.0, rtol=1e-12, reason="round-off", what="shares sum to 1")
    assert_close(shares[0], rms[0].ravel() / rms[0].sum(), rtol=1e-12, reason="round-off")
    assert np.all(shares[3] == 0.0), "a window with zero total should get zero shares"
    with pytest.raises(ValueError):
        order_features(-rms - 1.0)
