"""The grey-box refit's curves: its physical functions, yaw factor and coefficient curves with delta-method bands.

:class:`GreyBoxCurves` is the part of :class:`vivbench.models.GreyBoxRefit` that
turns the fitted spline coefficients and their covariance (``coef_``, ``cov_``,
``covariances_``) into curves on a wind grid: Y1, e1, e2, C_L
(:meth:`~GreyBoxCurves.physical_curves`), the yaw factor
(:meth:`~GreyBoxCurves.yaw_curve`), the coefficient curves a_ki(U) of
docs/concepts.md (coefficient curves) (:meth:`~GreyBoxCurves.curves`) and the
share of each covariance component in their bands
(:meth:`~GreyBoxCurves.band_components`), every band by the delta method at ``level``.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import xarray as xr
from scipy.stats import norm

from vivbench.models.curve_support import curves_dataset
from vivbench.models.greybox_physics import section_factors
from vivbench.models.protocol import section_names

__all__ = ["FUNCTIONS", "GreyBoxCurves"]

#: The unknown functions, in the order of the coefficient rows.
FUNCTIONS = ("Y1", "e1", "e2", "C_L")


class GreyBoxCurves:
    """Curves and bands of a fitted grey-box refit (a base of :class:`vivbench.models.GreyBoxRefit`)."""

    def _z(self) -> float:
        return float(norm.ppf(0.5 + 0.5 * self.level))

    def _bands(self, value: np.ndarray, grad: np.ndarray):
        """value (...), grad (..., P) -> lower, upper by the delta method."""
        P = grad.shape[-1]  # the spline block (curves at yaw 0 do not depend on the yaw coefficient)
        sd = np.sqrt(np.maximum(np.einsum("...a,ab,...b->...", grad, self.cov_[:P, :P], grad), 0.0))
        return value - self._z() * sd, value + self._z() * sd

    def band_alternatives(self) -> dict:
        """The fitted model with each of its covariances (``covariances_``) in force, by name (copies; the
        model's own band is ``band``). Empty for a model without alternative covariances."""
        self._check_fitted()
        out = {}
        for name, cov in (getattr(self, "covariances_", None) or {}).items():
            alt = copy.copy(self)
            alt.cov_ = cov
            out[name] = alt
        return out

    def default_wind(self, step: float = 0.1) -> np.ndarray:
        """The fitted data's wind range on multiples of ``step`` (m/s)."""
        self._check_fitted()
        lo, hi = self.wind_range_
        return np.arange(math.ceil(lo / step - 1e-9), math.floor(hi / step + 1e-9) + 1) * step

    def physical_curves(self, wind=None) -> xr.Dataset:
        """Y1, e1, e2, C_L against wind with their bands (``<name>_lower``, ``<name>_upper``)."""
        self._check_fitted()
        wind = self.default_wind() if wind is None else np.atleast_1d(np.asarray(wind, dtype=float))
        B = self.basis_values(wind)  # (n, M)
        M = self.n_basis
        data = {}
        for f, name in enumerate(FUNCTIONS):
            val = B @ self.coef_[f]
            grad = np.zeros((wind.size, 4 * M))
            grad[:, f * M:(f + 1) * M] = B
            lo, hi = self._bands(val, grad)
            data[name] = ("wind", val, {"units": "1", "long_name": f"{name} at wind U (yaw 0)"})
            data[f"{name}_lower"] = ("wind", lo, {"units": "1", "long_name": f"lower {self.level:g} band of {name}"})
            data[f"{name}_upper"] = ("wind", hi, {"units": "1", "long_name": f"upper {self.level:g} band of {name}"})
        return xr.Dataset(data, coords={"wind": ("wind", wind, {"units": "m/s"}),
                                        "reduced_velocity": ("wind", self._ur(wind), {"units": "1"})})

    def yaw_curve(self, yaw=None) -> xr.Dataset:
        """The yaw coefficient c and the factor 1 - c sin^2(yaw) on Y1 and C_L, with bands.

        Parameters
        ----------
        yaw : array_like or None, degrees (default -30..30 by 1)

        Returns
        -------
        xarray.Dataset
            ``yaw_coef`` (scalar, with ``yaw_coef_lower``, ``yaw_coef_upper``)
            and ``yaw_factor`` (yaw) with ``yaw_factor_lower``/``_upper``;
            c = 0 with a zero-width band when the yaw factor was not fitted
            (attribute ``yaw_used`` 0).
        """
        self._check_fitted()
        yaw = np.arange(-30.0, 30.5, 1.0) if yaw is None else np.atleast_1d(np.asarray(yaw, dtype=float))
        c = float(self.yaw_coef_)
        sd = float(np.sqrt(max(self.cov_[-1, -1], 0.0))) if self.yaw_used_ else 0.0
        lo, hi = max(c - self._z() * sd, 0.0), c + self._z() * sd  # c >= 0 is a bound of the fit
        s2 = np.sin(np.radians(yaw)) ** 2
        att = {"units": "1"}
        return xr.Dataset(
            {"yaw_coef": ((), c, {**att, "long_name": "c of the yaw factor 1 - c sin^2(yaw) on Y1 and C_L"}),
             "yaw_coef_lower": ((), lo, {**att, "long_name": f"lower {self.level:g} band of yaw_coef (>= 0)"}),
             "yaw_coef_upper": ((), hi, {**att, "long_name": f"upper {self.level:g} band of yaw_coef"}),
             "yaw_factor": ("yaw", 1.0 - c * s2, {**att, "long_name": "factor on Y1 and C_L at the yaw angle"}),
             "yaw_factor_lower": ("yaw", 1.0 - hi * s2, {**att, "long_name": f"lower {self.level:g} band"}),
             "yaw_factor_upper": ("yaw", 1.0 - lo * s2, {**att, "long_name": f"upper {self.level:g} band"})},
            coords={"yaw": ("yaw", yaw, {"units": "degree", "long_name": "mean wind's angle to the span's normal"})},
            attrs={"yaw_used": int(self.yaw_used_)})

    def _curve_parts(self, wind: np.ndarray):
        """p_i(U) (4, n) of the curves with every section at U, and their gradients in coef (4, n, 4 M)."""
        S, M = self.n_sections_, self.n_basis
        U = np.repeat(wind[:, None], S, axis=1)
        k = section_factors(U, self.bridge, self.phi_, self.beta_).sum(axis=1)  # (n, 4)
        B = self.basis_values(wind)
        F = B @ self.coef_.T  # (n, 4)
        Y, E1, E2, CL = F.T
        p = np.stack([k[:, 0] * CL, k[:, 1] * Y - self.bridge.omega * self.bridge.damping_ratio,
                      k[:, 2] * Y * E1, k[:, 3] * Y * E2])  # (4, n)
        grad = np.zeros((4, wind.size, 4, M))
        grad[0, :, 3] = k[:, 0, None] * B
        grad[1, :, 0] = k[:, 1, None] * B
        grad[2, :, 0] = (k[:, 2] * E1)[:, None] * B
        grad[2, :, 1] = (k[:, 2] * Y)[:, None] * B
        grad[3, :, 0] = (k[:, 3] * E2)[:, None] * B
        grad[3, :, 2] = (k[:, 3] * Y)[:, None] * B
        return p, grad.reshape(4, wind.size, 4 * M)

    #: Components of the bands, each a covariance of coef: name -> how it is formed from ``covariances_``.
    BAND_COMPONENTS = ("sandwich", "smoothing_bias", "wind")

    def band_components(self, wind=None) -> xr.Dataset:
        """Standard deviation of every curve a_ki(U) from each component of the band's covariance alone.

        Components: "sandwich" (the estimator's variance, residuals correlated
        within blocks), "smoothing_bias" (prior-averaged squared smoothing
        bias), "wind" (second moment of refits with the wind perturbed by
        draws of the anemometers' error, :mod:`vivbench.models.greybox_wind`);
        NaN for a component the fit did not compute.
        The chosen band's variance is the sum of the squares of its
        components (``band_sd_used``).

        Returns
        -------
        xarray.Dataset
            ``band_sd`` (component, equation, order, wind), m^(1-i)/s, and
            ``band_sd_used`` (component) 1 where the band holds the component.
        """
        self._check_fitted()
        wind = self.default_wind() if wind is None else np.atleast_1d(np.asarray(wind, dtype=float))
        _, grad = self._curve_parts(wind)
        P = grad.shape[-1]
        covs = self.covariances_
        parts = {"sandwich": covs.get("sandwich"),
                 "smoothing_bias": (covs["sandwich_bias"] - covs["sandwich"]
                                    if "sandwich_bias" in covs and "sandwich" in covs else None),
                 "wind": covs.get("wind")}
        used = {"posterior": (), "sandwich": ("sandwich",), "sandwich_bias": ("sandwich", "smoothing_bias"),
                "bootstrap": (), "bootstrap_bias": ("smoothing_bias",),
                "sandwich_bias_wind": ("sandwich", "smoothing_bias", "wind")}[self.band]
        fac = np.abs(self.phi_[:, None] ** (1 - np.arange(4))[None, :])  # (S, 4)
        out = np.full((len(self.BAND_COMPONENTS), self.n_sections_, 4, wind.size), np.nan)
        for j, name in enumerate(self.BAND_COMPONENTS):
            c = parts[name]
            if c is None:
                continue
            var = np.einsum("...a,ab,...b->...", grad, c[:P, :P], grad)
            out[j] = fac[..., None] * np.sqrt(np.maximum(var, 0.0))[None]
        units = "m^(1-order) s-1"
        return xr.Dataset(
            {"band_sd": (("component", "equation", "order", "wind"), out,
                         {"units": units, "long_name": "standard deviation of a curve from one band component alone"}),
             "band_sd_used": (("component",), np.array([int(n in used) for n in self.BAND_COMPONENTS]),
                              {"units": "1", "long_name": "1 where the band's covariance holds the component"})},
            coords={"component": list(self.BAND_COMPONENTS), "equation": section_names(self.n_sections_),
                    "order": np.arange(4), "wind": ("wind", wind, {"units": "m/s"})})

    def curves(self, wind=None) -> xr.Dataset:
        """Coefficient curves a_ki(U) of docs/concepts.md (coefficient curves) with delta-method bands.

        a_ki = phi_k^(1-i) p_i(U), p_i the amplitude-equation coefficients with
        every section at wind U (p_1 includes -zeta w).

        Returns
        -------
        xarray.Dataset
            ``curves``, ``curves_lower``, ``curves_upper`` (equation, order, wind), m^(1-i)/s.
        """
        self._check_fitted()
        wind = self.default_wind() if wind is None else np.atleast_1d(np.asarray(wind, dtype=float))
        if wind.ndim != 1 or not np.all(np.isfinite(wind)) or np.any(wind <= 0):
            raise ValueError("wind must be a 1-D array of finite positive speeds in m/s")
        p, grad = self._curve_parts(wind)
        M = self.n_basis
        lo, hi = self._bands(p, grad.reshape(4, wind.size, 4 * M))
        fac = self.phi_[:, None] ** (1 - np.arange(4))[None, :]  # (S, 4)
        point = fac[..., None] * p[None]
        lower = np.where(fac[..., None] >= 0, fac[..., None] * lo[None], fac[..., None] * hi[None])
        upper = np.where(fac[..., None] >= 0, fac[..., None] * hi[None], fac[..., None] * lo[None])
        return curves_dataset(point, lower, upper, wind, band=f"{self.level:g} delta-method band",
                              model=type(self).__name__)
