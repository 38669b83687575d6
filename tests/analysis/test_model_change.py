"""The time-varying check of the varying campaign model: refitted before and after every split of the events."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.helpers import assert_close, assert_not_close, change_records


def test_model_change_scan_locates_a_step_and_stays_quiet_without_one():
    from vivbench.analysis.changes import model_change_scan
    from vivbench.models import VaryingCoefficientSINDy

    recs = change_records(change_at=5, scale=0.6)
    model = VaryingCoefficientSINDy(n_bootstrap=0, n_basis=(8,)).fit(recs)
    scan = model_change_scan(model, recs, n_permutations=49)
    assert scan["change_index"] == 5 and scan["detected"]
    assert scan["split_gain"][5] == np.nanmax(scan["split_gain"])
    quiet = change_records()
    model = VaryingCoefficientSINDy(n_bootstrap=0, n_basis=(8,)).fit(quiet)
    scan = model_change_scan(model, quiet, n_permutations=49)
    assert not scan["detected"]
    # One event's winds reach beyond the others' (held-out: extrapolated curves): at most that one is flagged.
    assert scan["misfit_flag"].sum() <= 1


@settings(max_examples=25, deadline=None)
@given(strata=st.lists(st.integers(0, 3), min_size=2, max_size=15), seed=st.integers(0, 100))
def test_stratified_permutations_keep_every_event_in_its_stratum(strata, seed):
    from vivbench.analysis.changes import stratified_permutations

    strata = np.array(strata)
    perms = stratified_permutations(strata, 20, np.random.default_rng(seed))
    assert perms.shape == (20, strata.size)
    assert np.all(np.sort(perms, axis=1) == np.arange(strata.size))  # orderings of all events
    assert np.all(strata[perms] == strata[None, :])  # each position keeps its stratum


def test_one_stratum_is_a_plain_permutation():
    from vivbench.analysis.changes import stratified_permutations

    perms = stratified_permutations(np.zeros(8, dtype=int), 50, np.random.default_rng(0))
    assert len({tuple(p) for p in perms}) > 40


def test_wind_strata_group_events_of_similar_wind():
    from vivbench.analysis.changes import wind_strata
    from vivbench.core import Record
    from vivbench.models import VaryingCoefficientSINDy

    rng = np.random.default_rng(1)
    recs = []
    centres = [6.0, 12.0, 6.5, 11.5, 9.0, 6.2, 12.2, 9.2]
    for e, c in enumerate(centres):
        t = np.arange(0.0, 600.0, 1.0)
        U = c + 0.5 * np.sin(2 * np.pi * t / 300 + e)
        A = 0.05 + 0.05 * rng.random(t.size)
        recs.append(Record(event_id=f"E{e}", t=t, A=A[:, None], U=U[:, None], dA=(-0.01 * A)[:, None]))
    model = VaryingCoefficientSINDy(n_bootstrap=0, n_basis=(8,), wind_smoothing_s=0.0).fit(recs)
    strata = wind_strata(model.event_statistics(recs), size=3)
    # ranks by mean wind: 6.0, 6.2, 6.5 | 9.0, 9.2, 11.5 | 12.0, 12.2 (2 left over: their own stratum)
    assert strata.tolist() == [0, 2, 0, 1, 1, 0, 2, 1]


def test_standardised_statistic_locates_the_step_and_rejects_unknown_names():
    import pytest

    from vivbench.analysis.changes import model_change_scan
    from vivbench.models import VaryingCoefficientSINDy

    recs = change_records(change_at=5, scale=0.6)
    model = VaryingCoefficientSINDy(n_bootstrap=0, n_basis=(8,)).fit(recs)
    scan = model_change_scan(model, recs, n_permutations=49, statistic="standardised")
    assert scan["change_index"] == 5 and scan["detected"]
    # The observed gains are not rescaled in the output; only the test statistic is.
    assert scan["split_gain"][5] == np.nanmax(scan["split_gain"])
    with pytest.raises(ValueError, match="statistic must be"):
        model_change_scan(model, recs, n_permutations=9, statistic="median")


def test_scan_without_yaw_terms_equals_the_scan_of_the_yaw_free_columns():
    from vivbench.analysis.changes import statistics_change_scan

    rng = np.random.default_rng(3)
    E, n, M, J1 = 10, 60, 3, 2  # columns ordered (amplitude power i: 4, yaw power j: J1, basis m: M)
    p = 4 * J1 * M
    X = rng.standard_normal((E, n, p))
    y = X[..., :M].sum(axis=2) + rng.standard_normal((E, n)) * (1.0 + (np.arange(E) >= 5))[:, None]
    full = [{"G": np.einsum("eni,enj->eij", X, X), "b": np.einsum("eni,en->ei", X, y), "yy": (y * y).sum(axis=1),
             "n": np.full(E, n), "P": np.eye(p), "penalty": 0.0, "keep": np.ones(p, dtype=bool), "n_basis": M}]
    cols = np.flatnonzero((np.arange(p) // M) % J1 == 0)
    sliced = [{**full[0], "G": full[0]["G"][:, cols[:, None], cols], "b": full[0]["b"][:, cols], "P": np.eye(cols.size),
               "keep": np.ones(cols.size, dtype=bool)}]
    a = statistics_change_scan(full, n_permutations=19, null="permutation", yaw_terms=False)
    b = statistics_change_scan(sliced, n_permutations=19, null="permutation")
    c = statistics_change_scan(full, n_permutations=19, null="permutation")
    assert_close(a["split_gain"], b["split_gain"])
    assert a["p_value"] == b["p_value"]
    assert_not_close(a["split_gain"], c["split_gain"], what="split gain with the yaw columns")  # the yaw columns did count


def test_offset_gains_equal_the_penalised_fit_with_a_linear_offset_after_the_split():
    from vivbench.analysis.change_offset import linear_columns, offset_gain, offset_parts

    rng = np.random.default_rng(5)
    E, n, M, J1 = 9, 80, 4, 2  # columns ordered (amplitude power i: 4, yaw power j: J1, basis m: M)
    p = 4 * J1 * M
    X = rng.standard_normal((E, n, p))
    y = X[..., :M].sum(axis=2) + rng.standard_normal((E, n))
    P = np.kron(np.eye(4 * J1), np.diff(np.eye(M), 2, axis=0).T @ np.diff(np.eye(M), 2, axis=0))
    keep = np.ones(p, dtype=bool)
    keep[3 * J1 * M:] = False  # the cubic order dropped: the offset's column is still the linear one's sum
    stats = [{"G": np.einsum("eni,enj->eij", X, X), "b": np.einsum("eni,en->ei", X, y), "yy": (y * y).sum(axis=1),
              "n": np.full(E, n), "P": P, "penalty": 0.3, "keep": keep, "n_basis": M}]
    v = linear_columns(stats[0])
    assert np.flatnonzero(v).tolist() == list(range(J1 * M, J1 * M + M))  # order 1, yaw power 0
    splits = np.arange(2, E - 1)
    order = rng.permutation(E)
    gain = offset_gain(offset_parts(stats), order[None], splits)[0]
    # the same from the augmented normal equations, solved directly
    st = stats[0]
    idx = np.flatnonzero(keep)
    G, b = st["G"], st["b"]
    mu = st["penalty"] * np.trace(G.sum(axis=0)) / np.trace(P)
    Pk = mu * P[np.ix_(idx, idx)]

    def objective(A_idx):  # min over c, delta of ||y - X c - delta x_after||^2 + c' mu P c
        Xa = np.concatenate([X[..., idx], np.zeros((E, n, 1))], axis=2)
        Xa[A_idx, :, -1] = X[A_idx][..., v].sum(axis=2)
        Xf, yf = Xa.reshape(E * n, -1), y.reshape(-1)
        Hp = Xf.T @ Xf
        Hp[:-1, :-1] += Pk
        Hp[np.diag_indices_from(Hp)] += 1e-10 * np.trace(Xf[:, :-1].T @ Xf[:, :-1]) / idx.size
        c = np.linalg.solve(Hp, Xf.T @ yf)
        r = yf - Xf @ c
        return r @ r + c[:-1] @ Pk @ c[:-1], r @ r

    base, base_rss = objective(np.array([], dtype=int))
    for k, g in zip(splits, gain):
        assert_close(g, (base - objective(order[k:])[0]) / base_rss, rtol=1e-6,
                     reason="the scan's ridge of 1e-10 of the mean diagonal enters its objective, not this one's")


def test_offset_statistic_locates_a_damping_step_and_stays_quiet_without_one():
    from vivbench.analysis.changes import model_change_scan
    from vivbench.models import VaryingCoefficientSINDy

    # from event 6 on, the net linear coefficient is 0.004 1/s lower at every wind: a step of damping
    recs = change_records(change_at=5, shift=-0.004)
    model = VaryingCoefficientSINDy(n_bootstrap=0, n_basis=(8,)).fit(recs)
    scan = model_change_scan(model, recs, n_permutations=99, statistic="offset")
    assert scan["change_index"] == 5 and scan["detected"]
    quiet = change_records()
    model = VaryingCoefficientSINDy(n_bootstrap=0, n_basis=(8,)).fit(quiet)
    assert not model_change_scan(model, quiet, n_permutations=99, statistic="offset")["detected"]
