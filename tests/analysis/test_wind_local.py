"""Evidence of dynamics by wind (vivbench.analysis.wind_local) and held-out losses summed by wind bin."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.analysis.test_selection import _Poly, _always_flag
from tests.helpers import assert_close
from vivbench.analysis.held_out import dynamics_by_wind, held_out_losses
from vivbench.analysis.selection import Candidate, ModelSelection
from vivbench.analysis.wind_local import window_wind, wind_bin_edges, wind_bins_of
from vivbench.core.record import Record


def _mixed_records(seed: int = 0) -> list[Record]:
    """Six events at 8 m/s whose envelope relaxes (dA/dt = 0.05 - 0.02 A) and six at 11-13 m/s whose
    envelope follows the wind with no lag (A = 2.5 + 0.1 (U - 12)): dynamics at one wind, none at the other."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 300.0, 1.0)
    out = []
    for e in range(12):
        if e % 2 == 0:
            U = np.full(t.size, 8.0)
            a0 = rng.uniform(0.0, 5.0)
            A = 2.5 + (a0 - 2.5) * np.exp(-0.02 * t)
        else:
            U = 12.0 + np.sin(2 * np.pi * t / 60.0 + rng.uniform(0, 2 * np.pi))
            A = 2.5 + 0.1 * (U - 12.0)
        A = A + 0.01 * rng.standard_normal(t.size)
        out.append(Record(event_id=f"E{e:03d}", t=t, A=A[:, None], U=U[:, None], dA=np.gradient(A, t)[:, None]))
    return out


def test_windows_are_flagged_only_at_winds_where_the_dynamics_beat_the_null():
    from vivbench.models import QuasiSteadyAmplitude

    recs = _mixed_records()
    sel = ModelSelection(candidates=[Candidate(name="linear", model=_Poly(2))], n_perturbations=0, verdict=_always_flag,
                         null_model=QuasiSteadyAmplitude(wind_smoothing_s=0.0), wind_bins=4).fit(recs)
    assert sel.dynamics_shown_
    shown = sel.dynamics_by_wind_[0]
    low = wind_bins_of(np.array([8.0]), sel.wind_edges_)[0]
    assert shown[low] and not shown[np.arange(shown.size) != low].any()
    windows = (np.array([0.0, 100.0]), np.array([50.0, 150.0]))
    assert sel.identifiable(recs[0], *windows).all()       # 8 m/s: the envelope relaxes
    assert not sel.identifiable(recs[1], *windows).any()   # 11-13 m/s: it follows the wind
    ev = sel.evidence()
    assert ev["wind_bins"] == 4 and ev["dynamics_by_wind"]["shown"] == [bool(x) for x in shown]
    assert "no window is flagged at those winds" in sel.evidence_text()
    # the campaign-wide test alone flags both
    wide = ModelSelection(candidates=[Candidate(name="linear", model=_Poly(2))], n_perturbations=0, verdict=_always_flag,
                          null_model=QuasiSteadyAmplitude(wind_smoothing_s=0.0)).fit(recs)
    assert wide.dynamics_by_wind_ is None and wide.identifiable(recs[1], *windows).all()


@given(n_bins=st.integers(1, 8), seed=st.integers(0, 2**16))
@settings(max_examples=25, deadline=None)
def test_losses_by_wind_bin_sum_to_the_losses(n_bins, seed):
    recs = _mixed_records(seed % 7)
    model = _Poly(2).fit(recs[:6])
    edges = wind_bin_edges(recs, n_bins)
    for criterion in ("output", "derivative"):
        total = held_out_losses(model, recs, criterion)
        by_bin = held_out_losses(model, recs, criterion, wind_edges=edges)
        assert by_bin.shape == (len(recs), edges.size - 1)
        assert_close(by_bin.sum(axis=1), total, rtol=1e-9, reason="the same squares summed in another order")


def test_wind_bins_hold_equal_shares_and_a_constant_wind_is_one_bin():
    rng = np.random.default_rng(1)
    U = rng.uniform(2.0, 12.0, size=(6000, 2))
    rec = Record(event_id="E1", t=np.arange(6000.0), A=np.ones((6000, 2)), U=U)
    edges = wind_bin_edges([rec], 6)
    counts = np.bincount(wind_bins_of(U, edges).ravel(), minlength=6)
    assert edges.size == 7 and counts.min() >= 0.16 * U.size
    still = Record(event_id="E2", t=np.arange(10.0), A=np.ones((10, 1)), U=np.full((10, 1), 7.0))
    assert wind_bin_edges([still], 6).tolist() == [7.0, np.inf]
    assert wind_bins_of(np.array([np.nan, -1.0, 99.0]), edges).tolist() == [-1, 0, 5]


def test_dynamics_by_wind_needs_enough_events_in_a_bin():
    rng = np.random.default_rng(2)
    model = rng.uniform(0.5, 1.0, size=(10, 3))
    null = model + np.array([1.0, -0.2, 1.0])   # the null loses in bins 0 and 2, wins in bin 1
    null[3:, 2] = model[3:, 2] = 0.0            # bin 2: only three events have samples
    shown, excess, se, n = dynamics_by_wind(model, null, min_events=4)
    assert shown.tolist() == [True, False, False] and n.tolist() == [10, 10, 3]
    assert_close(excess[:2], [10.0, -2.0]) and np.isnan(excess[2])


def test_window_wind_is_the_mean_over_each_window():
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 100.0, 0.5)
    U = rng.normal(8.0, 1.0, size=(t.size, 2))
    U[10:20, 1] = np.nan
    start, end = np.array([0.0, 3.0, 40.0, 99.9]), np.array([10.0, 12.0, 60.0, 100.0])
    got = window_wind(U, t, start, end)
    for w in range(4):
        m = (t >= start[w]) & (t < end[w])
        want = [np.nanmean(U[m, k]) if np.isfinite(U[m, k]).any() else np.nan for k in range(2)]
        assert_close(got[w], np.array(want))


def test_the_output_error_simulates_each_side_of_a_gap_in_time_from_its_own_start():
    """A record whose samples stop for a while without NaN (a gap between a result's segments) is two runs: its
    held-out output error is that of its two pieces, each simulated from its own first amplitude."""
    recs = _mixed_records()
    model = _Poly(2).fit(recs[::2])
    rec = recs[0]
    t = np.where(rec.t < 150.0, rec.t, rec.t + 200.0)  # 200 s of samples missing after t = 149 s
    gapped = Record(event_id="E", t=t, A=rec.A, U=rec.U, dA=rec.dA)
    first, second = (Record(event_id="E", t=t[sl], A=rec.A[sl], U=rec.U[sl], dA=rec.dA[sl])
                     for sl in (slice(0, 150), slice(150, None)))
    whole = held_out_losses(model, [gapped], "output")[0]
    assert whole > 0
    assert_close(whole, held_out_losses(model, [first, second], "output").sum(), rtol=1e-12,
                 reason="the same runs simulated in another batch")
