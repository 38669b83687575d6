"""The binned baseline: per wind bin, least squares of dA_k/dt on [1, A_k, A_k^2, A_k^3]."""

from __future__ import annotations

import numpy as np
import pytest

from tests.helpers import assert_close
from vivbench.core import Record
from vivbench.models import BinnedPolynomial
from vivbench.validate import resolve_method


def _records(seed: int = 0) -> list:
    """Two sections, mean wind in three 0.5 m/s bins: [7.0, 7.5) and [7.5, 8.0) full, [9.0, 9.5) with 3 samples."""
    rng = np.random.default_rng(seed)
    out = []
    for e in range(2):
        n = 300
        U = np.repeat(rng.uniform(7.0, 7.99, n)[:, None], 2, axis=1) + np.array([-0.001, 0.001])
        if e == 1:
            U[:3] = 9.2  # a bin with too few samples for four coefficients
        A = rng.uniform(0.01, 0.3, (n, 2))
        dA = 0.01 * A - 0.2 * A**3 + 0.05 * (U - 7.5) * A + 1e-4 * rng.standard_normal((n, 2))
        dA[5, 1] = np.nan  # a missing derivative: skipped for section 2 only
        out.append(Record(event_id=f"E{e}", t=np.arange(n, dtype=float), A=A, U=U, dA=dA))
    return out


def test_binned_fit_is_the_least_squares_of_each_bin_and_equation():
    records = _records()
    model = resolve_method("binned")
    assert isinstance(model, BinnedPolynomial)
    assert model.fit(records) is model
    assert not hasattr(model, "identifiable")  # the baseline flags nothing
    np.testing.assert_array_equal(model.bins_, [14, 15, 18])
    A = np.concatenate([r.A for r in records])
    U = np.concatenate([r.U for r in records])
    dA = np.concatenate([r.dA for r in records])
    b = np.floor(U.mean(axis=1) / 0.5)
    for j, bj in enumerate(model.bins_):
        for k in range(2):
            sel = (b == bj) & np.isfinite(dA[:, k])
            assert model.n_fit_[j, k] == sel.sum()
            if sel.sum() < 4:
                assert np.isnan(model.coef_[j, k]).all()
                continue
            X = np.stack([np.ones(sel.sum()), A[sel, k], A[sel, k] ** 2, A[sel, k] ** 3], axis=1)
            expected = np.linalg.lstsq(X, dA[sel, k], rcond=None)[0]
            assert_close(model.coef_[j, k], expected, rtol=1e-7,
                         reason="the fit scales the columns to unit RMS before lstsq: rounding differs")
    # predict: the bin's polynomial; NaN in the bin left empty and outside the fitted bins
    rec = Record(event_id="p", t=np.arange(3.0), A=np.full((3, 2), 0.1),
                 U=np.array([[7.2, 7.2], [9.2, 9.2], [12.0, 12.0]]))
    pred = model.predict(rec)
    assert_close(pred[0], model.coef_[0] @ (0.1 ** np.arange(4)))
    assert np.isnan(pred[1:]).all()
    r = model.order_contributions(rec)
    assert r.shape == (3, 2, 4)
    assert_close(r[0].sum(-1), pred[0])
    c = model.curves([6.9, 7.2, 7.7, 8.2])
    assert c["curves"].shape == (2, 4, 4)
    assert_close(c["curves"].values[:, :, 1], model.coef_[0])
    assert_close(c["curves"].values[:, :, 2], model.coef_[1])
    assert np.isnan(c["curves"].values[:, :, [0, 3]]).all()
    assert len(model.equations()) == 3 * 2


def test_binned_bad_parameters_say_what_is_allowed():
    with pytest.raises(ValueError, match="bin_width"):
        BinnedPolynomial(bin_width=0.0).fit(_records())
    with pytest.raises(ValueError, match="min_samples"):
        BinnedPolynomial(min_samples=3).fit(_records())
