"""A trivial baseline: per bin of mean wind, a cubic polynomial of dA_k/dt in A_k fitted by least squares.

The floor a campaign-level model must beat: it knows nothing of the
physics (no smoothness in wind, no sharing between bins, no verdict), only
that within a narrow band of wind speeds dA_k/dt is a function of A_k.
"""

from __future__ import annotations

import json
from collections.abc import Sequence

import numpy as np
import xarray as xr

from vivbench.core.record import Record
from vivbench.io.binned_model import binned_model_dataset, read_binned_model, write_binned_model
from vivbench.models.protocol import ModelBase, fit_records, section_names

__all__ = ["BinnedPolynomial"]

_N_COEF = 4  # 1, A, A^2, A^3


class BinnedPolynomial(ModelBase):
    """dA_k/dt = sum_i c_bki A_k^i, one least-squares fit per bin b of the mean wind over sections.

    Parameters
    ----------
    bin_width : float, m/s
        Width of the wind bins; bin b holds the samples with
        b * bin_width <= mean_k U_k < (b + 1) * bin_width.
    min_samples : int
        A bin-equation with fewer valid samples (or a rank-deficient design)
        is left empty: NaN coefficients, NaN predictions. At least 4 (one per
        coefficient).

    Attributes
    ----------
    bins_ : ndarray of int, shape (n_bins,)
        Indices b of the bins that hold any fitted sample, ascending.
    coef_ : ndarray, shape (n_bins, S, 4)
        c_bki in m^(1-i)/s; NaN for empty bin-equations.
    n_fit_ : ndarray of int, shape (n_bins, S)
        Samples per bin-equation.
    n_sections_ : int
    wind_range_ : ndarray, shape (2,), m/s
        Smallest and largest fitted mean wind.

    Notes
    -----
    No ``identifiable``: the baseline flags nothing. ``curves(wind)`` are
    piecewise constant (the bin's coefficients), NaN outside the fitted bins.
    """

    def __init__(self, *, bin_width: float = 0.5, min_samples: int = _N_COEF):
        self.bin_width = bin_width
        self.min_samples = min_samples

    def _check_params(self) -> None:
        w = self.bin_width
        if isinstance(w, bool) or not isinstance(w, (int, float)) or not np.isfinite(w) or w <= 0:
            raise ValueError(f"bin_width must be a finite positive wind speed in m/s; got {w!r}")
        m = self.min_samples
        if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < _N_COEF:
            raise ValueError(f"min_samples must be an integer >= {_N_COEF} (one sample per coefficient); got {m!r}")

    def _bin_of(self, U: np.ndarray) -> np.ndarray:
        """Bin index (float, NaN where the mean wind is not finite) of each sample's mean wind over sections."""
        with np.errstate(invalid="ignore"):
            mean = np.mean(U, axis=1)
        return np.floor(mean / float(self.bin_width))

    def fit(self, records: Sequence[Record]) -> "BinnedPolynomial":
        """Fit every bin-equation by least squares on [1, A_k, A_k^2, A_k^3].

        Parameters
        ----------
        records : sequence of Record with ``dA``; samples with a NaN in A_k,
            dA_k or any section's U are skipped.

        Returns
        -------
        self
        """
        self._check_params()
        records = fit_records(records)
        S = records[0].n_sections
        A = np.concatenate([r.A for r in records])
        dA = np.concatenate([r.dA for r in records])
        U = np.concatenate([r.U for r in records])
        b = self._bin_of(U)
        ok = np.isfinite(b)[:, None] & np.isfinite(A) & np.isfinite(dA)  # (n, S)
        if not ok.any():
            raise ValueError("no sample with finite A, U and dA to fit")
        bins = np.unique(b[ok.any(axis=1)]).astype(int)
        coef = np.full((bins.size, S, _N_COEF), np.nan)
        n_fit = np.zeros((bins.size, S), dtype=int)
        for j, bj in enumerate(bins):
            in_bin = b == bj
            for k in range(S):
                sel = in_bin & ok[:, k]
                n_fit[j, k] = int(sel.sum())
                if n_fit[j, k] >= self.min_samples:
                    coef[j, k] = _cubic_lstsq(A[sel, k], dA[sel, k])
        mean = np.mean(U[np.isfinite(b)], axis=1)
        self.bins_ = bins
        self.coef_ = coef
        self.n_fit_ = n_fit
        self.n_sections_ = S
        self.wind_range_ = np.array([mean.min(), mean.max()])
        return self

    def _coef_at(self, bin_index: np.ndarray) -> np.ndarray:
        """Coefficients (n, S, 4) of the bins ``bin_index`` (n,); NaN for bins not fitted."""
        out = np.full((bin_index.size, self.n_sections_, _N_COEF), np.nan)
        finite = np.isfinite(bin_index)
        pos = np.searchsorted(self.bins_, bin_index[finite].astype(int))
        pos = np.minimum(pos, self.bins_.size - 1)
        hit = self.bins_[pos] == bin_index[finite].astype(int)
        rows = np.flatnonzero(finite)[hit]
        out[rows] = self.coef_[pos[hit]]
        return out

    def order_contributions(self, record) -> np.ndarray:
        """r_i = c_bki A_k^i with b the sample's bin, shape (n_samples, S, 4), m/s; NaN outside fitted bins."""
        record = self._check_record(record)
        c = self._coef_at(self._bin_of(record.U))
        return c * record.A[:, :, None] ** np.arange(_N_COEF)

    def predict(self, record) -> np.ndarray:
        """dA/dt, shape (n_samples, S), m/s: the sum of the order contributions."""
        return self.order_contributions(record).sum(axis=-1)

    def curves(self, wind) -> xr.Dataset:
        """Coefficient curves a_ki(U): the coefficients of U's bin, piecewise constant.

        Parameters
        ----------
        wind : array_like, shape (n_wind,), m/s (every section at this wind)

        Returns
        -------
        xarray.Dataset
            ``curves`` (equation, order, wind) in m^(1-i)/s, NaN outside the
            fitted bins; ``curves_lower``, ``curves_upper`` NaN (no band).
        """
        self._check_fitted()
        wind = np.atleast_1d(np.asarray(wind, dtype=float))
        if wind.ndim != 1 or not np.all(np.isfinite(wind)):
            raise ValueError("wind must be a 1-D array of finite speeds in m/s")
        c = self._coef_at(np.floor(wind / float(self.bin_width)))  # (n_wind, S, 4)
        out = np.transpose(c, (1, 2, 0))
        dims = ("equation", "order", "wind")
        units = {"units": "m^(1-order) s-1"}
        return xr.Dataset({"curves": (dims, out, units), "curves_lower": (dims, np.full_like(out, np.nan), units),
                           "curves_upper": (dims, np.full_like(out, np.nan), units)},
                          coords={"equation": section_names(self.n_sections_), "order": np.arange(_N_COEF),
                                  "wind": ("wind", wind, {"units": "m/s"})},
                          attrs={"model": type(self).__name__})

    def equations(self, precision: int = 3) -> list[str]:
        """One line per bin and equation, e.g. ``"U in [8, 8.5) m/s: dA1/dt = c0 + c1 A1 + c2 A1^2 + c3 A1^3"``."""
        self._check_fitted()
        w = float(self.bin_width)
        out = []
        for j, b in enumerate(self.bins_):
            for k in range(self.n_sections_):
                c = self.coef_[j, k]
                terms = " ".join(f"{'+' if x >= 0 else '-'} {abs(x):.{precision}g}{p}" for x, p in
                                 zip(c, ("", f" A{k + 1}", f" A{k + 1}^2", f" A{k + 1}^3")))
                rhs = "nan" if not np.all(np.isfinite(c)) else (terms[2:] if terms[0] == "+" else "-" + terms[2:])
                out.append(f"U in [{b * w:g}, {(b + 1) * w:g}) m/s: dA{k + 1}/dt = {rhs}")
        return out

    def save(self, path):
        """Write the fitted model (:mod:`vivbench.io.binned_model`, with its format version) atomically; returns the path."""
        self._check_fitted()
        ds = binned_model_dataset(vars(self), params_json=json.dumps(self.get_params(), sort_keys=True),
                                  equations=section_names(self.n_sections_))
        return write_binned_model(ds, path)

    @classmethod
    def load(cls, path) -> "BinnedPolynomial":
        """A fitted model from a file written by :meth:`save`."""
        params, fitted = read_binned_model(path)
        model = cls(**params)
        for name, value in fitted.items():
            setattr(model, name, value)
        return model


def _cubic_lstsq(a: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least squares of y on [1, a, a^2, a^3] (columns scaled to unit RMS); NaN when rank-deficient."""
    X = a[:, None] ** np.arange(_N_COEF)
    scale = np.sqrt(np.mean(X**2, axis=0))
    if np.any(scale == 0):
        return np.full(_N_COEF, np.nan)
    sol, _res, rank, _sv = np.linalg.lstsq(X / scale, y, rcond=None)
    return sol / scale if rank == _N_COEF else np.full(_N_COEF, np.nan)
