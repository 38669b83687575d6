"""Assemble an event in memory (docs/formats.md) from sensor arrays and an optional truth."""

from __future__ import annotations

import json
import numbers
from collections.abc import Mapping, Sequence

import numpy as np
import xarray as xr

from vivbench.core.errors import InputError
from vivbench.io.event_schema import (CHANGE_VARIABLES, COEF_UNITS, CURVE_UNITS, FORMAT, FORMAT_VERSION, TRUTH_YAW_NAME,
                                      validate_event)

__all__ = ["build_event"]

_TRUTH_KEYS = ("time", "U", "A", "r", "regime", "config", "coef", "feature", "tau",
               "damping_ratio", "mass_factor", "aero_factor", "curves", "wind", "yaw")


def build_event(
    *,
    event_id: str,
    start_time: str,
    source: str,
    span_azimuth_deg: float,
    wind_time,
    u,
    v,
    w,
    accel_time,
    acc,
    truth: Mapping | None = None,
    attrs: Mapping | None = None,
    sections: Sequence[str] = ("S1", "S2", "S3"),
) -> xr.DataTree:
    """Assemble an event in memory and check it against the format.

    Parameters
    ----------
    event_id : str
        Identifier, also the file stem (letters, digits, ``_`` and ``-``).
    start_time : str
        ISO 8601 instant in UTC (``Z`` or ``+00:00``), e.g. "2012-01-08T10:00:00Z".
    source : {"synthetic", "field"}
    span_azimuth_deg : float
        Direction of the span axis, degrees clockwise from north.
    wind_time : array_like, shape (n_wind,), s
        Anemometer times since ``start_time`` (stored as float64).
    u, v, w : array_like, shape (n_wind, n_sections), m/s
        Wind components towards east, north and up; the dtype is kept
        (float32 sensor data read back bit-identically).
    accel_time : array_like, shape (n_acc,), s
        Accelerometer times since ``start_time`` (float64).
    acc : array_like, shape (n_acc, n_sections), m/s^2
        Vertical deck acceleration; the dtype is kept.
    truth : mapping, optional
        Synthetic ground truth with keys ``time`` (n_t,) s; ``U`` (n_t, n_sec)
        m/s; ``A`` (n_t, n_sec) m; ``r`` (n_t, n_sec, 4) m/s, contributions of
        the orders 0..3 to dA/dt; ``regime`` (n_t, n_sec) integers 1..4;
        ``config`` the generator configuration as a JSON string (or a mapping,
        dumped with sorted keys); optional ``coef`` (n_sec, n_features) float64
        exact coefficient matrix (row k gives dA_k/dt) with ``feature`` the
        n_features term names; optional ``tau`` regime threshold; optional slow
        changes (all three or none), dimensionless: ``damping_ratio`` (n_t,),
        ``mass_factor`` (n_t,) and ``aero_factor`` (n_t, 4); optional exact
        coefficient curves (docs/concepts.md (coefficient curves)) ``curves`` (n_sec, 4, n_wind) in
        m^(1-i)/s with ``wind`` (n_wind,) m/s, finite, positive and
        increasing.
    attrs : mapping, optional
        Extra root attributes: str, int or float scalars; names must not start
        with ``_`` nor replace the format's own attributes.
    sections : sequence of str
        Section labels, "S1".."Sn".

    Returns
    -------
    xarray.DataTree
        A tree that passes :func:`validate_event`.

    Raises
    ------
    ValueError
        Arguments of the wrong shape or type; :class:`EventFormatError` (a
        ``ValueError``) if the assembled event breaks the format.
    """
    sections = [str(s) for s in sections]
    n_sec = len(sections)
    label = f"event {event_id!r}"

    wind_time = _as_time(wind_time, "wind_time")
    accel_time = _as_time(accel_time, "accel_time")
    wind_vars = {}
    for name, values, long_name in (
        ("u", u, "wind velocity component towards east"),
        ("v", v, "wind velocity component towards north"),
        ("w", w, "wind velocity component upwards"),
    ):
        values = _as_float(values, name, (wind_time.size, n_sec), "(n_wind, n_sections)")
        wind_vars[name] = (("time", "section"), values, {"units": "m/s", "long_name": long_name})
    acc = _as_float(acc, "acc", (accel_time.size, n_sec), "(n_acc, n_sections)")

    root = xr.Dataset(attrs=_root_attrs(event_id, start_time, source, span_azimuth_deg, attrs))
    wind = xr.Dataset(wind_vars, coords=_sensor_coords(wind_time, sections))
    accel = xr.Dataset(
        {"acc": (("time", "section"), acc, {"units": "m/s^2", "long_name": "vertical deck acceleration"})},
        coords=_sensor_coords(accel_time, sections),
    )
    groups = {"/": root, "/wind": wind, "/accel": accel}
    if truth is not None:
        groups["/truth"] = _truth_dataset(truth, sections)
    tree = xr.DataTree.from_dict(groups)
    validate_event(tree, name=label)
    return tree


def _as_time(values, what: str) -> np.ndarray:
    t = np.asarray(values, dtype=np.float64)
    if t.ndim != 1:
        raise InputError(f"{what} must be one-dimensional (n_samples,); got shape {t.shape}")
    return t


def _as_float(values, what: str, shape: tuple, shape_text: str) -> np.ndarray:
    a = np.asarray(values)
    if a.dtype.kind not in "fiu":
        raise InputError(f"{what} must hold real numbers; got dtype {a.dtype}")
    if a.dtype.kind != "f":
        a = a.astype(np.float64)
    if a.shape != shape:
        raise InputError(f"{what} must have shape {shape_text} = {shape}; got {a.shape}")
    return a


def _sensor_coords(time: np.ndarray, sections: list[str]) -> dict:
    return {
        "time": ("time", time, {"units": "s", "long_name": "time since start_time"}),
        "section": ("section", np.array(sections, dtype=str), {"long_name": "deck section"}),
    }


def _root_attrs(event_id, start_time, source, span_azimuth_deg, extra) -> dict:
    if not isinstance(span_azimuth_deg, numbers.Real) or isinstance(span_azimuth_deg, bool):
        raise InputError(f"span_azimuth_deg must be a real number of degrees; got {span_azimuth_deg!r}")
    out = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "event_id": event_id,
        "start_time": start_time,
        "source": source,
        "span_azimuth_deg": float(span_azimuth_deg),
    }
    for key, value in (extra or {}).items():
        if not isinstance(key, str) or not key or key.startswith("_"):
            raise InputError(f"extra attribute name {key!r} must be a non-empty str not starting with '_'")
        if key in out:
            raise InputError(f"extra attribute {key!r} would replace the format's own attribute; allowed: any other name")
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (str, numbers.Integral, numbers.Real)):
            raise InputError(
                f"extra attribute {key!r} must be a str, int or float scalar (netCDF-storable); got {type(value).__name__}"
            )
        out[key] = value
    return out


def _truth_dataset(truth: Mapping, sections: list[str]) -> xr.Dataset:
    unknown = sorted(set(truth) - set(_TRUTH_KEYS))
    if unknown:
        raise ValueError(f"unknown truth keys {unknown}; allowed: {list(_TRUTH_KEYS)}")
    missing = [k for k in ("time", "U", "A", "r", "regime", "config") if k not in truth]
    if missing:
        raise ValueError(f"truth lacks {missing}; required: time, U, A, r, regime, config")
    n_sec = len(sections)
    t = _as_time(truth["time"], "truth['time']")
    n_t = t.size
    U = _as_float(truth["U"], "truth['U']", (n_t, n_sec), "(n_t, n_sections)")
    A = _as_float(truth["A"], "truth['A']", (n_t, n_sec), "(n_t, n_sections)")
    r = _as_float(truth["r"], "truth['r']", (n_t, n_sec, 4), "(n_t, n_sections, 4)")
    regime = np.asarray(truth["regime"])
    if regime.shape != (n_t, n_sec):
        raise ValueError(f"truth['regime'] must have shape (n_t, n_sections) = {(n_t, n_sec)}; got {regime.shape}")
    if regime.dtype.kind not in "iu" and not (
        regime.dtype.kind == "f" and np.all(np.isfinite(regime)) and np.all(regime == np.round(regime))
    ):
        raise ValueError(f"truth['regime'] must hold integers 1..4; got dtype {regime.dtype}")
    config = truth["config"]
    if isinstance(config, Mapping):
        config = json.dumps(config, sort_keys=True)
    if not isinstance(config, str):
        raise ValueError(f"truth['config'] must be a JSON string or a mapping; got {type(config).__name__}")

    attrs = {"config_json": config}
    if truth.get("tau") is not None:
        attrs["tau"] = float(truth["tau"])
    ds = xr.Dataset(
        {
            "U": (("time", "section"), U, {"units": "m/s", "long_name": "mean wind speed perpendicular to the span"}),
            "A": (("time", "section"), A, {"units": "m", "long_name": "vibration amplitude of the averaged model"}),
            "r": (
                ("time", "section", "order"),
                r,
                {"units": "m/s", "long_name": "contribution of the order-i terms (A^i) to dA/dt"},
            ),
            "regime": (
                ("time", "section"),
                regime.astype(np.int8),
                {
                    "units": "1",
                    "long_name": "regime: 1 none, 2 slight, 3 medium, 4 strong self-excitation",
                },
            ),
        },
        coords={
            "time": ("time", t, {"units": "s", "long_name": "time since start_time"}),
            "section": ("section", np.array(sections, dtype=str), {"long_name": "deck section"}),
            "order": ("order", np.arange(4, dtype=np.int64), {"units": "1", "long_name": "power of A"}),
        },
        attrs=attrs,
    )
    if truth.get("coef") is not None:
        coef = np.asarray(truth["coef"], dtype=np.float64)
        feature = truth.get("feature")
        if feature is None:
            raise ValueError("truth['coef'] needs truth['feature'], the names of its columns")
        feature = np.array([str(f) for f in feature], dtype=str)
        if coef.shape != (n_sec, feature.size):
            raise ValueError(
                f"truth['coef'] must have shape (n_sections, n_features) = {(n_sec, feature.size)}; got {coef.shape}"
            )
        ds["coef"] = (
            ("equation", "feature"),
            coef,
            {
                "units": COEF_UNITS,
                "long_name": "exact coefficients of dA_k/dt over the library",
                "description": "row k gives dA_k/dt (m/s); column (i, j) multiplies A^i U^j of the section it names",
            },
        )
        ds = ds.assign_coords(
            equation=("equation", np.array(sections, dtype=str), {"long_name": "section whose dA/dt the row gives"}),
            feature=("feature", feature, {"long_name": "library term, pysindy-style name"}),
        )
    elif truth.get("feature") is not None:
        raise ValueError("truth['feature'] given without truth['coef']")
    if (truth.get("curves") is None) != (truth.get("wind") is None):
        raise ValueError("truth['curves'] and truth['wind'] come together: the curves and their wind grid (m/s)")
    if truth.get("curves") is not None:
        wind = np.asarray(truth["wind"], dtype=np.float64)
        if wind.ndim != 1 or wind.size < 2 or not np.all(np.isfinite(wind)) or np.any(wind <= 0) \
                or np.any(np.diff(wind) <= 0):
            raise ValueError("truth['wind'] must be a 1-D increasing array of at least 2 finite positive speeds (m/s)")
        curves = _as_float(truth["curves"], "truth['curves']", (n_sec, 4, wind.size), "(n_sections, 4, n_wind)")
        ds["curves"] = (
            ("equation", "order", "wind"),
            curves.astype(np.float64),
            {"units": CURVE_UNITS,
             "long_name": "exact coefficient of A_k^order in dA_k/dt at mean wind U, yaw 0 (docs/concepts.md (coefficient curves))"},
        )
        ds = ds.assign_coords(
            equation=("equation", np.array(sections, dtype=str), {"long_name": "section whose dA/dt the row gives"}),
            wind=("wind", wind, {"units": "m/s", "long_name": "mean wind speed perpendicular to the span"}),
        )
    if truth.get("yaw") is not None:
        yaw = _as_float(truth["yaw"], "truth['yaw']", (n_t, n_sec), "(n_t, n_sections)")  # range: validate_event
        ds["yaw"] = (("time", "section"), yaw.astype(np.float64), {"units": "degree", "long_name": TRUTH_YAW_NAME})
    given = [k for k in CHANGE_VARIABLES if truth.get(k) is not None]
    if given and len(given) != len(CHANGE_VARIABLES):
        raise ValueError(f"truth has {given} but the slow changes need all of {list(CHANGE_VARIABLES)}")
    for name in given:
        dims, long_name = CHANGE_VARIABLES[name]
        shape = (n_t,) if dims == ("time",) else (n_t, 4)
        values = _as_float(truth[name], f"truth[{name!r}]", shape, "(n_t,)" if dims == ("time",) else "(n_t, 4)")
        ds[name] = (dims, values.astype(np.float64), {"units": "1", "long_name": long_name})
    return ds
