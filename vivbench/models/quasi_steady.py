"""A quasi-steady amplitude map: the envelope as a function of the wind alone, with no dynamics.

Where a bridge's amplitude is slaved to the wind (a forced response, or a limit cycle that follows
the wind slowly), the amplitude at each instant is a function of the wind at that instant, and any
split of the dynamics between the orders of A fits the data: the regimes are not identifiable. The
map ``A_k = g_k(U)`` is the null model of that case. :class:`vivbench.analysis.ModelSelection`
compares its held-out output error with the dynamic candidates': a campaign whose dynamic models do
not predict held-out events better than this map holds no evidence of its dynamics, and its
verdict flags no window.

``g_k`` is a cubic P-spline (B-splines on uniform intervals over the campaign's wind, a
second-difference penalty chosen by generalised cross-validation) of each section's amplitude
on the sections' mean wind, smoothed as the dynamic models' is.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.models.protocol import as_record
from vivbench.models.simulate import Simulation, nmse
from vivbench.library.splines import bspline_basis, difference_penalty, uniform_knots
from vivbench.preprocess.wind_smoothing import smooth_wind
from vivbench.regression.penalised import penalised_solve, penalty_scale, quadratic_error

__all__ = ["QuasiSteadyAmplitude"]


class QuasiSteadyAmplitude:
    """The amplitude of each section as a smooth function of the smoothed mean wind, A_k = g_k(U).

    Parameters
    ----------
    wind_smoothing_s : float, s, >= 0
        Gaussian smoothing of the measured wind before the map (:meth:`measured_wind`); that of the
        dynamic models it is compared with.
    n_basis : int, >= 5
        B-splines over the campaign's wind range.
    penalties : sequence of float, > 0
        Relative penalties (times trace(B^T B) / trace(D^T D)) among which generalised
        cross-validation chooses, per section.

    Attributes
    ----------
    knots_ : ndarray, shape (n_basis + 4,), m/s
    coef_ : ndarray, shape (S, n_basis), m
    penalty_ : ndarray, shape (S,), the chosen relative penalty of each section
    n_sections_ : int
    """

    def __init__(self, *, wind_smoothing_s: float = 30.0, n_basis: int = 12,
                 penalties: Sequence[float] = tuple(10.0 ** np.arange(-6.0, 2.5, 1.0))):
        self.wind_smoothing_s = wind_smoothing_s
        self.n_basis = n_basis
        self.penalties = penalties

    def get_params(self) -> dict:
        """The constructor's parameters."""
        return {"wind_smoothing_s": self.wind_smoothing_s, "n_basis": self.n_basis, "penalties": self.penalties}

    def set_params(self, **params) -> "QuasiSteadyAmplitude":
        """Set constructor parameters; returns self."""
        for k, v in params.items():
            if k not in self.get_params():
                raise InputError(f"QuasiSteadyAmplitude has no parameter {k!r}; "
                                 f"allowed: {', '.join(self.get_params())}")
            setattr(self, k, v)
        return self

    def _validate(self) -> None:
        if not (np.isfinite(self.wind_smoothing_s) and self.wind_smoothing_s >= 0):
            raise InputError(f"wind_smoothing_s must be a number of seconds >= 0; got {self.wind_smoothing_s!r}")
        if int(self.n_basis) != self.n_basis or self.n_basis < 5:
            raise InputError(f"n_basis must be an integer >= 5; got {self.n_basis!r}")
        pen = np.asarray(self.penalties, dtype=float)
        if pen.ndim != 1 or pen.size == 0 or not np.all(np.isfinite(pen) & (pen > 0)):
            raise InputError(f"penalties must be a non-empty sequence of positive numbers; got {self.penalties!r}")

    def measured_wind(self, record: Record) -> Record:
        """The record with its wind smoothed as at fit (``wind_smoothing_s``)."""
        return smooth_wind(as_record(record), float(self.wind_smoothing_s))

    @staticmethod
    def _wind(record: Record) -> np.ndarray:
        """The sections' mean wind, shape (n,), m/s (NaN where any section's is)."""
        U = np.asarray(record.U, dtype=float)
        return np.where(np.isfinite(U).all(axis=1), np.mean(U, axis=1), np.nan)

    def fit(self, records: Sequence[Record]) -> "QuasiSteadyAmplitude":
        """Fit each section's map on the records' amplitudes and smoothed winds.

        Parameters
        ----------
        records : sequence of Record (A, U of shape (n, S), m and m/s), the measured records

        Returns
        -------
        self
        """
        self._validate()
        recs = [self.measured_wind(as_record(r, k)) for k, r in enumerate(records)]
        if not recs:
            raise InputError("no records to fit")
        S = recs[0].n_sections
        if any(r.n_sections != S for r in recs):
            raise InputError("every record must have the same number of sections")
        U = np.concatenate([self._wind(r) for r in recs])
        A = np.concatenate([np.asarray(r.A, dtype=float) for r in recs])
        finite_U = U[np.isfinite(U)]
        if finite_U.size == 0:
            raise InputError("no sample with a finite wind")
        M = int(self.n_basis)
        self.knots_ = uniform_knots(float(finite_U.min()), float(finite_U.max()), M)
        B = bspline_basis(U, self.knots_)
        P = difference_penalty(M)
        pen = np.asarray(self.penalties, dtype=float)
        self.coef_ = np.zeros((S, M))
        self.penalty_ = np.zeros(S)
        for k in range(S):
            ok = np.isfinite(U) & np.isfinite(A[:, k])
            n = int(ok.sum())
            if n <= M:
                raise InputError(f"section {k}: {n} valid samples, too few for a map of {M} B-splines")
            Bk, y = B[ok], A[ok, k]
            G, b, yy = Bk.T @ Bk, Bk.T @ y, float(y @ y)
            # Generalised cross-validation over the penalty grid, every penalty's solve at once.
            lam = pen * penalty_scale(G, P)
            c = penalised_solve(G, b, P, lam, ridge=0.0)  # (n_pen, M)
            H = G + lam[:, None, None] * P
            edf = np.trace(np.linalg.solve(H, np.broadcast_to(G, H.shape)), axis1=-2, axis2=-1)
            rss = np.maximum(quadratic_error(c, G, b, yy), 0.0)
            best = int(np.argmin(n * rss / np.maximum(n - edf, 1.0) ** 2))
            self.penalty_[k], self.coef_[k] = pen[best], c[best]
        self.n_sections_ = S
        return self

    def amplitude(self, record: Record) -> np.ndarray:
        """The map's amplitudes g_k(U) on a record as it is (no smoothing), shape (n, S), m."""
        if not hasattr(self, "coef_"):
            raise InputError("this QuasiSteadyAmplitude is not fitted: call fit(records) first")
        record = as_record(record)
        if record.n_sections != self.n_sections_:
            raise InputError(f"the record has {record.n_sections} sections; the map was fitted on {self.n_sections_}")
        return bspline_basis(self._wind(record), self.knots_) @ self.coef_.T

    def predict(self, record: Record) -> np.ndarray:
        """dA/dt of the map along the record, d g_k(U(t)) / dt, shape (n, S), m/s."""
        record = as_record(record)
        A = self.amplitude(record)
        if record.n_samples < 2:
            return np.full(A.shape, np.nan)
        return np.gradient(A, record.t, axis=0)

    def simulate(self, record: Record, t0: float | None = None, t1: float | None = None, A0=None) -> Simulation:
        """The map's amplitudes over [t0, t1] on the record's grid (no state: ``A0`` is not used).

        Returns
        -------
        Simulation, with ``A_sim`` = g_k(U) and ``A_meas`` the record's A over the span
        """
        record = as_record(record)
        t = record.t
        i0 = int(np.argmin(np.abs(t - (t[0] if t0 is None else float(t0)))))
        i1 = int(np.argmin(np.abs(t - (t[-1] if t1 is None else float(t1))))) + 1
        sl = slice(i0, i1)
        sub = Record(event_id=record.event_id, t=t[sl], A=record.A[sl], U=record.U[sl], dA=None)
        A_sim = self.amplitude(sub)
        return Simulation(t=t[sl], A_sim=A_sim, A_meas=record.A[sl], stopped_at=None, reason=None,
                          nmse=nmse(A_sim, record.A[sl]), covered=1.0,
                          windows=np.zeros(max(i1 - i0 - 1, 0), dtype=int))
