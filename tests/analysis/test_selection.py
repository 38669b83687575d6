"""Held-out model selection (vivbench.analysis.selection): folds, the one-standard-error set, the choice."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.helpers import assert_close, bell_records
from vivbench.analysis.held_out import event_folds, held_out_loss, one_se_set, shared_groups
from vivbench.analysis.selection import (LIMIT_TIME_CONSTANTS, POOLED_COMPLEXITY, SINGLE_SECTION_SHARE, Candidate,
                                         ModelSelection, perturbed_wind, varying_selection, wind_error_scale,
                                         without_yaw)
from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.models.simulate import Simulation


class _Poly:
    """dA/dt = sum_{i < order} c_i A^i, fitted by least squares over every sample (a model of the protocol)."""

    def __init__(self, order: int = 2):
        self.order = order

    def get_params(self):
        return {"order": self.order}

    def set_params(self, **params):
        for k, v in params.items():
            setattr(self, k, v)
        return self

    def fit(self, records):
        A = np.concatenate([r.A[:, 0] for r in records])
        dA = np.concatenate([r.dA[:, 0] for r in records])
        self.coef_ = np.linalg.lstsq(A[:, None] ** np.arange(self.order), dA, rcond=None)[0]
        return self

    def order_contributions(self, record):
        out = np.zeros(record.A.shape + (4,))
        for i, c in enumerate(self.coef_):
            out[..., i] = c * record.A**i
        return out

    def predict(self, record):
        return self.order_contributions(record).sum(axis=-1)

    def simulate(self, record, t0, t1):
        i0, i1 = np.searchsorted(record.t, t0), np.searchsorted(record.t, t1) + 1
        t = record.t[i0:i1]
        x = np.empty(t.size)
        x[0] = record.A[i0, 0]
        for n in range(t.size - 1):  # explicit Euler on the record's grid: a toy
            x[n + 1] = x[n] + (t[n + 1] - t[n]) * np.polyval(self.coef_[::-1], x[n])
        return Simulation(t=t, A_sim=x[:, None], A_meas=record.A[i0:i1], stopped_at=None, reason=None,
                          nmse=np.zeros(1), covered=1.0, windows=np.zeros(t.size - 1, dtype=int))


def _linear_records(n_events: int, slope: float, seed: int = 0, noise: float = 0.02) -> list[Record]:
    """Envelopes of dA/dt = 0.05 - slope A (exact decays to 0.05 / slope), measured dA/dt with noise."""
    rng = np.random.default_rng(seed)
    out = []
    for e in range(n_events):
        t = np.arange(0.0, 200.0, 1.0)
        a_inf = 0.05 / slope
        a0 = rng.uniform(0.0, 2 * a_inf)
        A = a_inf + (a0 - a_inf) * np.exp(-slope * t)
        dA = 0.05 - slope * A + noise * rng.standard_normal(t.size)
        out.append(Record(event_id=f"E{e:03d}", t=t, A=A[:, None], U=np.full((t.size, 1), 8.0), dA=dA[:, None]))
    return out


@given(n=st.integers(2, 40), k=st.integers(2, 10), seed=st.integers(0, 2**16))
@settings(max_examples=40, deadline=None)
def test_event_folds_partition_every_event_once(n, k, seed):
    fold = event_folds(n, k, seed)
    assert fold.shape == (n,)
    counts = np.bincount(fold)
    assert counts.size == min(n, k) and counts.min() >= 1 and counts.max() - counts.min() <= 1
    assert np.array_equal(fold, event_folds(n, k, seed))  # same seed, same folds


def test_event_folds_needs_two_events():
    with pytest.raises(InputError, match="at least 2 events"):
        event_folds(1, 5)


def test_one_se_set_keeps_candidates_within_one_standard_error():
    losses = np.array([[1.0, 1.0, 1.0, 1.0],    # best, total 4
                       [1.1, 0.9, 1.2, 1.0],    # +0.2, diffs (0.1, -0.1, 0.2, 0): se = 2 * std(ddof=1)
                       [2.0, 2.0, 2.0, 2.1]])   # +4.1, se = 2 * 0.05
    in_set, excess, se = one_se_set(losses)
    assert_close(excess, [0.0, 0.2, 4.1])
    assert_close(se[1], 2 * np.std([0.1, -0.1, 0.2, 0.0], ddof=1))
    assert in_set.tolist() == [True, True, False]


def test_selection_prefers_the_simpler_model_unless_the_data_demand_more():
    # The data follow dA/dt = 0.05 - 0.02 A: the constant model (order 1) cannot follow the decay.
    recs = _linear_records(10, slope=0.02)
    sel = ModelSelection(candidates=[Candidate(name="const", model=_Poly(1), complexity=0),
                                     Candidate(name="linear", model=_Poly(2), complexity=1),
                                     Candidate(name="quadratic", model=_Poly(3), complexity=2)],
                         n_folds=5, n_perturbations=0).fit(recs)
    assert sel.chosen_ == "linear"
    assert not sel.in_set_[0]
    A = np.linspace(0.0, 5.0, 11)
    assert_close(np.polyval(sel.model_.coef_[::-1], A), 0.05 - 0.02 * A, atol=0.01,
                 reason="dA/dt noise 0.02 m/s, as large as the signal, on 2000 samples")
    # held out: each event's loss comes from a model fitted without it
    assert sel.losses_.shape == (3, 10) and np.all(sel.losses_ > 0)
    ev = sel.evidence()
    assert ev["chosen"] == "linear" and [c["in_set"] for c in ev["candidates"]][1]
    assert "linear" in sel.evidence_text()


def test_selection_with_the_derivative_criterion_and_one_candidate():
    recs = _linear_records(4, slope=0.02)
    sel = ModelSelection(candidates=[Candidate(name="linear", model=_Poly(2))], criterion="derivative",
                         n_perturbations=0).fit(recs)
    assert sel.chosen_ == "linear" and sel.losses_.shape == (1, 4)
    # the protocol passes through to the chosen model
    assert_close(sel.predict(recs[0]), sel.model_.predict(recs[0]))


def test_held_out_loss_counts_a_stopped_run_as_missed():
    recs = _linear_records(2, slope=0.02)
    m = _Poly(2).fit(recs)
    assert np.isfinite(held_out_loss(m, recs[0]))

    class Stopped(_Poly):
        def simulate(self, record, t0, t1):
            sim = super().simulate(record, t0, t1)
            sim.A_sim[5:] = np.nan
            return sim

    s = Stopped(2).fit(recs)
    peak = np.nanmax(recs[0].A)
    # every sample after the stop is missed by the event's peak amplitude
    assert held_out_loss(s, recs[0]) >= (recs[0].t.size - 5) * peak**2


@pytest.mark.parametrize("bad, match", [
    (dict(candidates=[]), "at least one candidate"),
    (dict(criterion="aic"), "criterion must be one of"),
    (dict(n_folds=1), "n_folds must be"),
    (dict(n_perturbations=-1), "n_perturbations must be"),
    (dict(single_section_share=1.5), "single_section_share must be"),
    (dict(single_section_share=float("nan")), "single_section_share must be"),
    (dict(min_time_constants=0.0), "min_time_constants must be"),
    (dict(min_time_constants=float("inf")), "min_time_constants must be"),
])
def test_selection_refuses_bad_settings(bad, match):
    kw = dict(candidates=[Candidate(name="a", model=_Poly(1))])
    kw.update(bad)
    with pytest.raises(InputError, match=match):
        ModelSelection(**kw).fit(_linear_records(3, slope=0.02))


def test_candidate_names_are_unique():
    with pytest.raises(InputError, match="unique"):
        ModelSelection(candidates=[Candidate(name="a", model=_Poly(1)),
                                   Candidate(name="a", model=_Poly(2))]).fit(_linear_records(3, slope=0.02))


def test_wind_error_scale_is_the_spread_between_sections():
    t = np.arange(0.0, 3000.0, 1.0)
    rng = np.random.default_rng(1)
    base = 8.0 + np.sin(t / 300.0)
    offsets = np.array([-0.3, 0.0, 0.3])  # persistent offsets: rms deviation 0.245, x sqrt(3/2) = 0.3
    U = base[:, None] + offsets[None, :]
    rec = Record(event_id="E", t=t, A=np.full(U.shape, 0.1), U=U, dA=np.zeros(U.shape))
    assert_close(wind_error_scale(rec, 60.0), np.full(3, 0.3))
    one = Record(event_id="E", t=t, A=np.full((t.size, 1), 0.1), U=base[:, None], dA=np.zeros((t.size, 1)))
    assert_close(wind_error_scale(one, 60.0), [SINGLE_SECTION_SHARE * base.mean()], rtol=1e-3,
                 reason="the mean of the wind smoothed at 60 s, whose edges differ from the raw wind's")
    assert_close(wind_error_scale(one, 60.0, 0.06), 2.0 * wind_error_scale(one, 60.0))
    # the selection passes its prior on: a doubled share doubles the single section's error estimate
    recs1 = [Record(event_id=f"E{k}", t=t, A=np.full((t.size, 1), 0.1), U=base[:, None] + k,
                    dA=np.zeros((t.size, 1))) for k in range(3)]
    fits = [ModelSelection(candidates=[Candidate(name="a", model=_Poly(1))], n_perturbations=0,
                           single_section_share=share).fit(recs1) for share in (0.03, 0.06)]
    assert_close(fits[1].wind_error_, 2.0 * fits[0].wind_error_)
    assert fits[1].evidence()["single_section_share"] == 0.06  # recorded with the evidence, for reruns (the twin)
    pert = perturbed_wind(rec, np.full(3, 0.3), 60.0, rng)
    d = pert.U - rec.U
    assert_close(d.std(axis=0), np.full(3, 0.3))
    assert np.array_equal(pert.A, rec.A) and np.array_equal(pert.dA, rec.dA)


def _yaw_records(in_truth: bool):
    return bell_records(8, seed=3, duration_s=900.0, dt_s=1.0, mode_shape=np.array([1.0, 0.7]),
                        wind_period_s=(500.0, 80.0), amplitude_period_s=250.0, yaw_deg=40.0, yaw_period_s=600.0,
                        yaw_in_truth=in_truth, a0=0.002, a3=-2.0, noise_m_s=1e-4)


@pytest.mark.parametrize("in_truth, chosen_yaw", [(True, 1), (False, 0)])
def test_the_yaw_enters_only_where_the_campaign_demands_it(in_truth, chosen_yaw):
    sel = varying_selection(criterion="derivative", options={"yaw_degree": (0, 1)}, n_perturbations=1,
                            n_basis=(8,), n_bootstrap=10, wind_smoothing_s=0.0).fit(_yaw_records(in_truth))
    assert sel.model_.yaw_degree_ == chosen_yaw, sel.evidence_text()
    if in_truth:
        assert not sel.in_set_[0]  # the yaw-free model is significantly worse held out
    assert len(sel.perturbed_models_) == 1


@pytest.mark.parametrize("pinned, smoothing, grid", [
    ({}, {30.0}, None), ({"wind_smoothing_s": 15.0}, {15.0}, None),
    ({"options": {"wind_smoothing_s": (15.0, 60.0)}}, {15.0, 60.0}, None),
    ({"wind_smoothing_grid": (20.0, 30.0)}, {30.0}, (20.0, 30.0))])
def test_the_wind_smoothing_is_the_stated_prior_unless_given_or_among_the_options(pinned, smoothing, grid):
    # A grid given lets the campaign's cross-validation replace the prior; a smoothing pinned or among the
    # selection's options leaves the models none of their own.
    sel = varying_selection(**pinned)
    varying = [c for c in sel.candidates if c.options["model_class"] == "varying"]
    assert {c.model.wind_smoothing_s for c in sel.candidates} == smoothing  # the pooled candidates' too
    assert {c.model.wind_smoothing_s for c in sel.candidates if c.options["model_class"] == "pooled"} == smoothing
    assert {c.model.get_params()["wind_smoothing_grid"] for c in varying} == {grid}
    assert sel.null_model.wind_smoothing_s == (15.0 if "wind_smoothing_s" in pinned else 30.0)


def test_the_yaw_free_counterpart_has_the_same_options_without_the_yaw():
    from vivbench.analysis import yaw_free_counterpart

    sel = varying_selection()
    assert yaw_free_counterpart(sel.candidates, "yaw2-least").name == "yaw0-least"
    assert yaw_free_counterpart(sel.candidates, "yaw1-cv").name == "yaw0-cv"
    assert yaw_free_counterpart(sel.candidates, "yaw0-cv") is None  # takes no yaw
    assert yaw_free_counterpart(sel.candidates, "pooled") is None  # no yaw option at all
    assert yaw_free_counterpart([c for c in sel.candidates if c.name != "yaw0-cv"], "yaw1-cv") is None
    with pytest.raises(InputError, match="no candidate is named 'yaw3-cv'"):
        yaw_free_counterpart(sel.candidates, "yaw3-cv")


def test_without_yaw_keeps_the_yaw_free_candidates():
    sel = varying_selection(options={"yaw_degree": (0, 1), "penalty_choice": ("cv", "least")})
    assert len(sel.candidates) == 5
    assert [c.name for c in without_yaw(sel).candidates] == ["yaw0-cv", "yaw0-least", "pooled"]
    assert len(sel.candidates) == 5  # the original is left as it was
    with pytest.raises(InputError, match="needs the wind's yaw"):
        without_yaw(varying_selection(yaw_degree=1, options={"yaw_degree": (1,)}, model_classes=("varying",)))


def test_a_wind_input_option_is_named_by_its_value():
    sel = varying_selection(options={"yaw_degree": (0,), "wind_input": ("mean", "sum")}, model_classes=("varying",))
    assert [c.name for c in sel.candidates] == ["yaw0-mean", "yaw0-sum"]
    assert [c.options["wind_input"] for c in sel.candidates] == ["mean", "sum"]
    assert [c.complexity for c in sel.candidates] == [0, 0]  # an input, not a covariate: the loss decides


def test_two_events_give_no_held_out_choice_and_say_so():
    recs = _linear_records(2, slope=0.02)
    sel = ModelSelection(candidates=[Candidate(name="const", model=_Poly(1), complexity=0),
                                     Candidate(name="linear", model=_Poly(2), complexity=1)],
                         n_perturbations=0).fit(recs)
    assert sel.chosen_ == "const" and np.isnan(sel.losses_).all()
    assert "too few for a held-out choice" in sel.evidence_text()


def test_curve_bands_span_the_confidence_set_and_yaw_zero_outside_the_data_is_marked():
    recs = _yaw_records(False)
    # every record's yaw kept 10-50 degrees away from perpendicular: curves at yaw 0 are an extrapolation
    recs = [Record(event_id=r.event_id, t=r.t, A=r.A, U=r.U, dA=r.dA, yaw=30.0 + 0.5 * r.yaw) for r in recs]
    sel = varying_selection(criterion="derivative", options={"yaw_degree": (0, 1)}, n_perturbations=0,
                            n_basis=(8,), n_bootstrap=10, wind_smoothing_s=0.0).fit(recs)
    wind = np.linspace(8.0, 14.0, 13)
    c = sel.curves(wind)
    own = sel.model_.curves(wind)
    assert np.all(c["curves_lower"].values <= own["curves_lower"].values + 1e-15)
    assert np.all(c["curves_upper"].values >= own["curves_upper"].values - 1e-15)
    for m in sel.set_models_:
        inner = m.curves(wind)["curves"].values
        assert np.all((c["curves_lower"].values <= inner + 1e-15) & (inner <= c["curves_upper"].values + 1e-15))
    with_yaw = varying_selection(criterion="derivative", options={"yaw_degree": (1,)}, n_perturbations=0,
                                 n_basis=(8,), n_bootstrap=0, wind_smoothing_s=0.0).fit(recs)
    assert with_yaw.model_.yaw_extrapolated().all()
    assert with_yaw.curves(wind)["curves_extrapolated"].values.all()
    free = varying_selection(criterion="derivative", options={"yaw_degree": (0,)}, n_perturbations=0,
                             n_basis=(8,), n_bootstrap=0, wind_smoothing_s=0.0).fit(recs)
    assert not free.curves(wind)["curves_extrapolated"].values.any()


def _always_flag(model, record, window_start, window_end):
    """A verdict that flags every window regime 1 (the null model's test alone then decides)."""
    shape = (np.size(window_start), record.n_sections)
    return {"regime": np.ones(shape, dtype=int), "identifiable": np.ones(shape, dtype=bool)}


def _quasi_steady_records(n_events: int) -> list[Record]:
    """One section whose amplitude follows the wind with no lag: A = 0.01 (U - 6) / 4, dA/dt its derivative."""
    rng = np.random.default_rng(5)
    out = []
    for e in range(n_events):
        t = np.arange(0.0, 600.0, 1.0)
        U = 8.0 + 2.0 * np.sin(2 * np.pi * t / 400.0 + rng.uniform(0, 2 * np.pi))
        A = 0.01 * (U - 6.0) / 4.0 + 1e-4 * rng.standard_normal(t.size)
        out.append(Record(event_id=f"E{e:03d}", t=t, A=A[:, None], U=U[:, None],
                          dA=np.gradient(A, t)[:, None]))
    return out


class _FlaggingPoly(_Poly):
    """:class:`_Poly` whose own verdict flags every window (what ``vivbench pool`` writes then rests on the selection)."""

    def identifiable(self, record, window_start, window_end):
        return np.ones((np.size(window_start), record.n_sections), dtype=bool)


@pytest.mark.parametrize("slaved", [True, False])
def test_the_verdict_flags_only_campaigns_whose_dynamics_beat_the_quasi_steady_map(slaved):
    from vivbench.models import QuasiSteadyAmplitude

    recs = _quasi_steady_records(8) if slaved else _linear_records(8, slope=0.02)
    sel = ModelSelection(candidates=[Candidate(name="linear", model=_FlaggingPoly(2))], n_perturbations=0,
                         verdict=_always_flag, null_model=QuasiSteadyAmplitude(wind_smoothing_s=0.0)).fit(recs)
    start, end = np.array([0.0, 100.0]), np.array([50.0, 150.0])
    flags = sel.identifiable(recs[0], start, end)
    ev = sel.evidence()
    assert ev["dynamics_shown"] is (not slaved) and ev["null"]["in_set"] is slaved
    assert bool(flags.all()) is (not slaved) and bool(flags.any()) is (not slaved)
    # the verdicts vivbench pool writes (measured_verdicts) withhold the same windows
    np.testing.assert_array_equal(sel.measured_verdicts(recs[0], start, end)["identifiable"], flags)
    assert ("no window is flagged" in sel.evidence_text()) is slaved


def test_too_few_events_for_the_null_test_flag_nothing():
    from vivbench.models import QuasiSteadyAmplitude

    recs = _linear_records(2, slope=0.02)
    sel = ModelSelection(candidates=[Candidate(name="linear", model=_Poly(2))], n_perturbations=0,
                         verdict=_always_flag, null_model=QuasiSteadyAmplitude(wind_smoothing_s=0.0)).fit(recs)
    assert not sel.identifiable(recs[0], np.array([0.0]), np.array([50.0])).any()
    assert "no window is flagged" in sel.evidence_text()


def _step_records(step: bool) -> list[Record]:
    """Twelve events of one lock-in bell; with ``step`` the last six have a0 = -0.01 m/s instead of 0.002 m/s
    (a change of the balance that the wind does not carry)."""
    kw = dict(duration_s=900.0, dt_s=1.0, mode_shape=np.array([1.0]), wind_period_s=(500.0, 80.0),
              amplitude_period_s=250.0, a3=-2.0, noise_m_s=1e-4)
    first = bell_records(6, seed=5, a0=0.002, **kw)
    later = bell_records(6, seed=6, a0=-0.01 if step else 0.002, **kw)
    return first + [Record(event_id=f"E{6 + e:03d}", t=r.t, A=r.A, U=r.U, dA=r.dA) for e, r in enumerate(later)]


@pytest.mark.parametrize("step", [True, False])
def test_a_change_located_by_the_chosen_models_scan_withholds_every_flag(step):
    recs = _step_records(step)
    sel = varying_selection(criterion="derivative", options={"yaw_degree": (0,)}, n_perturbations=0, null=False,
                            n_basis=(8,), n_bootstrap=0, wind_smoothing_s=0.0)
    sel.verdict = _always_flag
    sel.fit(recs)
    ev = sel.evidence()
    assert ev["change"]["tested"] and ev["change"]["detected"] is step and ev["stationary"] is (not step)
    flags = sel.identifiable(recs[0], np.array([0.0, 100.0]), np.array([50.0, 150.0]))
    assert bool(flags.any()) is (not step)
    if step:
        assert ev["change"]["event"] in ("E005", "E006", "E007"), ev["change"]
        assert "locates a change from" in sel.evidence_text()
    unscanned = varying_selection(criterion="derivative", options={"yaw_degree": (0,)}, n_perturbations=0,
                                  null=False, change_scan=False, n_basis=(8,), n_bootstrap=0, wind_smoothing_s=0.0)
    unscanned.verdict = _always_flag
    assert unscanned.fit(recs).identifiable(recs[0], np.array([0.0]), np.array([50.0])).all()
    assert unscanned.evidence()["change"]["tested"] is False


def test_candidates_that_differ_only_in_final_parameters_share_a_group():
    from vivbench.models import QuasiSteadyAmplitude

    sel = varying_selection(options={"yaw_degree": (0, 1), "penalty_choice": ("cv", "least")})
    models = [c.model for c in sel.candidates] + [QuasiSteadyAmplitude(), _Poly(1), _Poly(1)]
    assert [c.name for c in sel.candidates] == ["yaw0-cv", "yaw0-least", "yaw1-cv", "yaw1-least", "pooled"]
    assert shared_groups(models) == [[0, 1], [2, 3], [4], [5], [6], [7]]


def test_grouped_held_out_fits_give_each_candidates_own_losses_and_final_fits():
    """The selection's losses and fitted models are those of every candidate fitted alone on every fold."""
    recs = _yaw_records(True)[:5]
    sel = varying_selection(criterion="output", options={"yaw_degree": (0, 1), "penalty_choice": ("cv", "least")},
                            n_perturbations=1, n_folds=3, n_basis=(6, 8), n_bootstrap=4, wind_smoothing_s=20.0,
                            null=False).fit(recs)
    fold = event_folds(len(recs), 3, 0)
    for c, losses in zip(sel.candidates, sel.losses_):
        expected = np.zeros(len(recs))
        for f in range(3):
            alone = type(c.model)(**{**c.model.get_params(), "n_bootstrap": 0})
            alone.fit([r for r, g in zip(recs, fold) if g != f])
            for i in np.flatnonzero(fold == f):
                expected[i] = held_out_loss(alone, recs[i], "output")
        assert np.array_equal(losses, expected), c.name
    chosen = sel.candidates[sel.chosen_index_].model
    alone = type(chosen)(**chosen.get_params()).fit(recs)
    assert sel.model_.to_dataset().identical(alone.to_dataset())
    others = [sel.candidates[i].model for i in np.flatnonzero(sel.in_set_) if i != sel.chosen_index_]
    for model, fitted in zip(others, sel.set_models_):
        assert fitted.to_dataset().identical(type(model)(**{**model.get_params(), "n_bootstrap": 0}).fit(recs)
                                             .to_dataset())


def _limit_after_100_s(model, record, window_start, window_end):
    """A verdict that flags every window: regime 1 before 100 s, the limit regime 3 from 100 s on."""
    start = np.atleast_1d(np.asarray(window_start, dtype=float))
    regime = np.repeat(np.where(start >= 100.0, 3, 1)[:, None], record.n_sections, axis=1)
    return {"regime": regime, "identifiable": np.ones(regime.shape, dtype=bool)}


class _PolyLimit(_Poly):
    """:class:`_Poly` whose own verdicts are :func:`_limit_after_100_s` (what ``vivbench pool`` writes)."""

    def window_verdicts(self, record, window_start, window_end):
        return _limit_after_100_s(self, record, window_start, window_end)


@pytest.mark.parametrize("slope, short", [(0.02, True), (0.05, False)])
def test_the_envelope_time_constant_comes_from_the_regime_1_windows_and_short_events_are_listed(slope, short):
    # dA/dt = 0.05 - slope A: the amplitude relaxes with the time constant 1 / slope; each event lasts 199 s,
    # under LIMIT_TIME_CONSTANTS (5) time constants of 50 s, over them for 20 s.
    recs = _linear_records(6, slope=slope)
    sel = ModelSelection(candidates=[Candidate(name="linear", model=_PolyLimit(2))], n_perturbations=0,
                         verdict=_limit_after_100_s).fit(recs)
    assert_close(sel.time_constant_s_, -1.0 / sel.model_.coef_[1], rtol=1e-6,
                 reason="the slope of a linear model by a relative finite difference of its prediction")
    assert_close(sel.time_constant_s_, 1.0 / slope, rtol=0.2, reason="the fitted slope, from noisy dA/dt")
    assert_close(sel.event_duration_s_, np.full(6, 199.0))
    assert (sel.short_events() == sel.event_ids_) is short and (sel.short_events() == []) is (not short)
    ev = sel.evidence()
    assert ev["short_events"] == sel.short_events() and ev["min_time_constants"] is None
    assert ("may be misread" in sel.evidence_text()) is short
    start, end = np.array([0.0, 100.0]), np.array([50.0, 150.0])
    # Without min_time_constants the limit regime is flagged; with it, only in events long enough.
    assert sel.identifiable(recs[0], start, end).all()
    sel.min_time_constants = LIMIT_TIME_CONSTANTS
    flags = sel.identifiable(recs[0], start, end)[:, 0]
    assert flags.tolist() == [True, not short]
    assert sel.measured_verdicts(recs[0], start, end)["identifiable"][:, 0].tolist() == [True, not short]
    assert ("are not flagged" in sel.evidence_text()) is short


def test_the_listed_short_events_are_those_the_restriction_withholds():
    # Events of 199 s, a time constant of about 20 s: under 5 time constants no event is short, under 12 all are.
    recs = _linear_records(6, slope=0.05)
    sel = ModelSelection(candidates=[Candidate(name="linear", model=_PolyLimit(2))], n_perturbations=0,
                         verdict=_limit_after_100_s, min_time_constants=12.0).fit(recs)
    assert sel.short_events() == sel.event_ids_ and sel.evidence()["short_events"] == sel.event_ids_
    assert "shorter than 12 envelope time constants" in sel.evidence_text()
    assert sel.identifiable(recs[0], np.array([100.0]), np.array([150.0])).tolist() == [[False]]
    sel.min_time_constants = None  # nothing withheld; the events under the prior are listed: none
    assert sel.short_events() == [] and sel.identifiable(recs[0], np.array([100.0]), np.array([150.0])).all()


def test_without_regime_1_windows_the_time_constant_is_unknown_and_no_limit_regime_is_flagged():
    def limit_everywhere(model, record, window_start, window_end):
        shape = (np.size(window_start), record.n_sections)
        return {"regime": np.full(shape, 4), "identifiable": np.ones(shape, dtype=bool)}

    recs = _linear_records(4, slope=0.05)
    sel = ModelSelection(candidates=[Candidate(name="linear", model=_Poly(2))], n_perturbations=0,
                         verdict=limit_everywhere, min_time_constants=2.0).fit(recs)
    assert np.isnan(sel.time_constant_s_) and sel.short_events() == sel.event_ids_
    assert "time constant is not identified" in sel.evidence_text()
    assert not sel.identifiable(recs[0], np.array([0.0]), np.array([50.0])).any()


def test_the_model_class_is_chosen_by_held_out_loss_as_a_structure_and_its_own_verdict_is_used():
    """PooledSINDy is scored on the same folds as the yaw-free varying candidates, with the complexity of one
    covariate: it is chosen only where no yaw-free varying candidate is in the confidence set, and the chosen
    model's verdict is its own through the protocol."""
    from vivbench.models.campaign import PooledSINDy
    from vivbench.models.model_input import measured_input
    from vivbench.regimes import model_verdicts

    recs = _yaw_records(False)
    sel = varying_selection(criterion="derivative", options={"yaw_degree": (0,), "penalty_choice": ("cv", "least")},
                            n_perturbations=0, n_basis=(8,), n_bootstrap=10, wind_smoothing_s=0.0, null=False,
                            change_scan=False).fit(recs)
    assert sel.names_ == ["yaw0-cv", "yaw0-least", "pooled"] and sel.scored_.all()
    assert [c.complexity for c in sel.candidates] == [0, 0, POOLED_COMPLEXITY] and POOLED_COMPLEXITY > 0
    total = sel.losses_.sum(axis=1)
    members = np.flatnonzero(sel.in_set_)
    simplest = [i for i in members if i < 2] or list(members)  # a yaw-free varying member first
    assert sel.chosen_index_ == min(simplest, key=lambda i: total[i])
    ev = {c["name"]: c for c in sel.evidence()["candidates"]}
    assert ev["pooled"]["options"] == {"model_class": "pooled", "wind_smoothing_s": 0.0}
    # The pooled class alone: chosen, and its windows get PooledSINDy's own regimes and, narrowed, its verdicts.
    alone = varying_selection(criterion="derivative", model_classes=("pooled",), n_perturbations=0,
                              n_bootstrap=10, block_s=100.0, wind_smoothing_s=0.0, null=False,
                              change_scan=False).fit(recs)
    assert alone.chosen_ == "pooled" and type(alone.chosen_model()) is PooledSINDy
    start, end = np.arange(0.0, 800.0, 100.0), np.arange(100.0, 900.0, 100.0)
    own = model_verdicts(alone.model_, measured_input(alone.model_, recs[0]), start, end)
    assert np.array_equal(alone.window_regimes(recs[0], start, end), own["regime"])
    flags = alone.identifiable(recs[0], start, end)
    assert not (flags & ~own["identifiable"]).any()
    assert alone.settings_text().startswith("PooledSINDy, terms per equation")
    with pytest.raises(InputError, match="model_classes must be distinct names"):
        varying_selection(model_classes=("varying", "greybox"))
