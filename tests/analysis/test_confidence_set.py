"""The confidence set of held-out selection (two paired tests over events) and the forward search over complexity."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import wilcoxon

from tests.analysis.test_selection import _Poly, _linear_records
from tests.helpers import assert_close
from vivbench.analysis.held_out import RANK_LEVEL, confidence_set, one_se_set, rank_p_values
from vivbench.analysis.selection import Candidate, ModelSelection
from vivbench.core.record import Record


def test_a_candidate_worse_on_nearly_every_event_leaves_the_set_though_one_event_hides_it_from_the_sum():
    # Nine events where the second candidate loses by 1, one dominant event where it wins by 5: the sum's
    # standard error is large (one-SE rule keeps it), but the signed-rank test sees the consistent loss.
    best = np.r_[np.ones(9), 100.0]
    other = np.r_[2.0 * np.ones(9), 95.0]
    losses = np.vstack([best, other])
    in_se, excess, se = one_se_set(losses)
    assert in_se.tolist() == [True, True]
    assert_close(excess[1], 4.0)
    in_set, excess2, se2, p = confidence_set(losses)
    assert p[0] == 1.0 and p[1] < RANK_LEVEL
    assert in_set.tolist() == [True, False]
    assert np.array_equal(excess, excess2) and np.array_equal(se, se2)


def test_rank_p_values_are_scipys_one_sided_signed_rank_test_against_the_best():
    rng = np.random.default_rng(3)
    losses = rng.gamma(2.0, 1.0, size=(4, 12))
    losses[2] = losses[0]  # a copy of another candidate: every difference to it zero when it is the best
    best = int(np.argmin(losses.sum(axis=1)))
    p = rank_p_values(losses)
    for i in range(4):
        d = losses[i] - losses[best]
        want = 1.0 if not np.any(d != 0) else wilcoxon(d, alternative="greater").pvalue
        assert_close(p[i], want)
    assert rank_p_values(losses[:, :1]).tolist() == [1.0] * 4  # one event: no test


@given(L=st.lists(st.lists(st.floats(0.0, 1e3), min_size=3, max_size=3), min_size=2, max_size=6))
@settings(max_examples=60, deadline=None)
def test_the_set_always_holds_the_best_and_is_within_the_one_se_set(L):
    losses = np.array(L).T  # (3 candidates, events)
    in_set, excess, se, p = confidence_set(losses)
    assert in_set[int(np.argmin(losses.sum(axis=1)))]
    assert np.all(~in_set | one_se_set(losses)[0])
    assert np.all((p >= 0) & (p <= 1))


def test_a_bad_rank_level_is_refused():
    with pytest.raises(ValueError, match="rank_level"):
        confidence_set(np.ones((2, 3)), rank_level=0.0)


def _drift_records(n_events: int, seed: int = 0) -> list[Record]:
    """Envelopes growing at a constant 0.01 m/s with noisy measured dA/dt: the constant model suffices."""
    rng = np.random.default_rng(seed)
    out = []
    for e in range(n_events):
        t = np.arange(0.0, 200.0, 1.0)
        A = rng.uniform(0.0, 0.5) + 0.01 * t
        dA = 0.01 + 0.002 * rng.standard_normal(t.size)
        out.append(Record(event_id=f"E{e:03d}", t=t, A=A[:, None], U=np.full((t.size, 1), 8.0), dA=dA[:, None]))
    return out


def _three_levels():
    return [Candidate(name="const", model=_Poly(1), complexity=0),
            Candidate(name="linear", model=_Poly(2), complexity=1),
            Candidate(name="quadratic", model=_Poly(3), complexity=2)]


def test_a_more_complex_candidate_is_scored_only_where_the_previous_level_was_needed():
    simple = ModelSelection(candidates=_three_levels(), n_perturbations=0).fit(_drift_records(8))
    assert simple.chosen_ == "const"
    assert simple.scored_.tolist() == [True, True, False]
    assert np.all(np.isnan(simple.losses_[2])) and not simple.in_set_[2]
    ev = {c["name"]: c for c in simple.evidence()["candidates"]}
    assert ev["quadratic"]["scored"] is False and ev["linear"]["scored"] is True
    assert "quadratic" in simple.evidence_text() and "not scored" in simple.evidence_text()

    needed = ModelSelection(candidates=_three_levels(), n_perturbations=0).fit(_linear_records(10, slope=0.02))
    assert needed.chosen_ == "linear" and needed.scored_.all()


def test_without_the_rank_test_the_set_is_the_one_se_set_and_the_evidence_says_so():
    sel = ModelSelection(candidates=_three_levels(), n_perturbations=0, rank_level=None).fit(_linear_records(10, 0.02))
    assert np.array_equal(sel.in_set_, one_se_set(sel.losses_)[0])
    assert np.all(np.isnan(sel.p_rank_)) and sel.evidence()["rank_level"] is None
    assert "signed-rank" not in sel.evidence_text()
    ranked = ModelSelection(candidates=_three_levels(), n_perturbations=0).fit(_linear_records(10, 0.02))
    assert ranked.evidence()["rank_level"] == RANK_LEVEL and "signed-rank p" in ranked.evidence_text()


@pytest.mark.parametrize("bad", [0.0, 1.0, "5%"])
def test_a_bad_rank_level_of_a_selection_is_refused(bad):
    from vivbench.core.errors import InputError

    with pytest.raises(InputError, match="rank_level must be None or a level in"):
        ModelSelection(candidates=_three_levels(), rank_level=bad).fit(_drift_records(4))
