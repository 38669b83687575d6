"""Where a campaign model's coefficient curves rest on data: the wind range per equation and the extrapolated parts.

A coefficient curve a_ki(U) at a wind no section k sample was fitted at is
an extrapolation of the model, not a finding. The curves' files mark it
with ``curves_extrapolated`` (equation, wind), the figures draw it apart
and the curve scores leave it out.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr

from vivbench.core.record import Record

__all__ = ["EXTRAPOLATED", "CURVE_UNITS", "curves_dataset", "data_wind_range", "mark_extrapolated", "extrapolated_mask",
           "curves_inside_data"]

#: Name of the marking variable in a curves dataset.
EXTRAPOLATED = "curves_extrapolated"

#: Units of the coefficient curves a_ki (of A_k^i in dA_k/dt).
CURVE_UNITS = "m^(1-order) s-1"


def curves_dataset(point: np.ndarray, lower: np.ndarray, upper: np.ndarray, wind: np.ndarray, *, band: str,
                   model: str) -> xr.Dataset:
    """The coefficient curves a_ki(U) of docs/concepts.md (coefficient curves) with their band, as a dataset.

    Parameters
    ----------
    point, lower, upper : ndarray, shape (S, 4, n_wind), m^(1-i)/s
        The curves and their band's limits (equation, order, wind).
    wind : ndarray, shape (n_wind,), m/s
    band : str
        What the band is (e.g. "0.95 bootstrap band"), for the limits' long names.
    model : str
        The model's class name (attribute ``model``).

    Returns
    -------
    xarray.Dataset
        ``curves``, ``curves_lower``, ``curves_upper`` (equation, order, wind).
    """
    dims = ("equation", "order", "wind")
    return xr.Dataset(
        {"curves": (dims, point, {"units": CURVE_UNITS,
                                  "long_name": "coefficient of A_k^order at wind U (docs/concepts.md (coefficient curves))"}),
         "curves_lower": (dims, lower, {"units": CURVE_UNITS, "long_name": f"lower {band}"}),
         "curves_upper": (dims, upper, {"units": CURVE_UNITS, "long_name": f"upper {band}"})},
        coords={"equation": [f"S{k + 1}" for k in range(point.shape[0])], "order": np.arange(4),
                "wind": ("wind", wind, {"units": "m/s"})},
        attrs={"model": model},
    )


def data_wind_range(records: Sequence[Record], *, need_dA: bool = True) -> np.ndarray:
    """Smallest and largest wind of each equation's fitted samples.

    Parameters
    ----------
    records : sequence of Record, the data a model was fitted on (its wind as
        the model saw it, e.g. smoothed)
    need_dA : bool
        Count only samples with a finite dA_k too (those a fit uses), when
        the record has dA.

    Returns
    -------
    ndarray, shape (S, 2), m/s
        [U_min, U_max] of section k's samples with finite A_k and U_k; NaN
        where section k has none.
    """
    records = list(records)
    if not records:
        raise ValueError("no records: the data's wind range is undefined")
    S = records[0].n_sections
    lo, hi = np.full(S, np.inf), np.full(S, -np.inf)
    for r in records:
        if r.n_sections != S:
            raise ValueError(f"record {r.event_id!r} has {r.n_sections} sections; the first has {S}")
        ok = np.isfinite(r.A) & np.isfinite(r.U)
        if need_dA and r.dA is not None:
            ok &= np.isfinite(r.dA)
        U = np.where(ok, r.U, np.nan)
        has = ok.any(axis=0)
        lo[has] = np.minimum(lo[has], np.nanmin(U[:, has], axis=0))
        hi[has] = np.maximum(hi[has], np.nanmax(U[:, has], axis=0))
    out = np.stack([lo, hi], axis=1)
    out[~np.isfinite(out).all(axis=1)] = np.nan
    return out


def extrapolated_mask(wind, wind_range) -> np.ndarray:
    """Bool (S, n_wind): the wind point lies outside equation k's data range (True also without data).

    Parameters
    ----------
    wind : array_like, shape (n_wind,), m/s
    wind_range : array_like, shape (S, 2), m/s (:func:`data_wind_range`)
    """
    wind = np.atleast_1d(np.asarray(wind, dtype=float))
    rng = np.asarray(wind_range, dtype=float)
    if rng.ndim != 2 or rng.shape[1] != 2:
        raise ValueError(f"wind_range must have shape (S, 2) ([U_min, U_max] per equation, m/s); got {rng.shape}")
    with np.errstate(invalid="ignore"):
        inside = (wind[None, :] >= rng[:, :1]) & (wind[None, :] <= rng[:, 1:])
    return ~inside


def mark_extrapolated(curves: xr.Dataset, wind_range) -> xr.Dataset:
    """A copy of a curves dataset with ``curves_extrapolated`` (equation, wind) added.

    Parameters
    ----------
    curves : xarray.Dataset
        Coordinates ``equation`` (S) and ``wind`` (m/s), e.g. a model's
        ``curves(wind)``; its values are not changed.
    wind_range : array_like, shape (S, 2), m/s
        The fitted data's [U_min, U_max] per equation (:func:`data_wind_range`).

    Returns
    -------
    xarray.Dataset
        With the boolean variable ``curves_extrapolated``: True where the
        curve's wind lies outside the equation's data (an extrapolation), or
        where ``curves`` already marked it so (a model that holds a covariate
        at a value outside its data marks its curves itself).
    """
    S = curves.sizes.get("equation")
    rng = np.asarray(wind_range, dtype=float)
    if S is None or "wind" not in curves.coords:
        raise ValueError("curves must have the coordinates equation and wind")
    if rng.shape != (S, 2):
        raise ValueError(f"wind_range must have shape ({S}, 2), one [U_min, U_max] per equation (m/s); got {rng.shape}")
    out = curves.copy()
    mask = extrapolated_mask(curves["wind"].values, rng)
    if EXTRAPOLATED in curves:  # the model's own marks (e.g. a covariate held outside its data) stay
        mask = mask | np.asarray(curves[EXTRAPOLATED].values, dtype=bool)
    out[EXTRAPOLATED] = (("equation", "wind"), mask,
                         {"long_name": "the curve's wind lies outside the fitted data's wind range of the equation "
                          "(an extrapolation of the model)"})
    return out


def curves_inside_data(curves: xr.Dataset, wind_range) -> np.ndarray:
    """The ``curves`` values (equation, order, wind) with NaN where they are extrapolations.

    Parameters
    ----------
    curves : xarray.Dataset with ``curves`` (equation, order, wind) and coordinate ``wind`` (m/s)
    wind_range : array_like, shape (S, 2), m/s, or None (nothing masked)

    Returns
    -------
    ndarray, shape (S, 4, n_wind), m^(1-i)/s
    """
    values = np.asarray(curves["curves"].values, dtype=float)
    if wind_range is None:
        return values.copy()
    return np.where(mark_extrapolated(curves, wind_range)[EXTRAPOLATED].values[:, None, :], np.nan, values)
