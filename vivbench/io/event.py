"""The event file format (docs/formats.md): build, check, write and read one event.

An event is one NetCDF-4 (HDF5) file, the same for field and synthetic data,
held in memory as an :class:`xarray.DataTree`::

    /                 attributes format, format_version, event_id, start_time,
                      source, span_azimuth_deg (+ any extra scalar attributes)
    /wind             time (time) float64 s; section (section) str
                      u, v, w (time, section) m/s: east, north, up; nominal 32 Hz
    /accel            time (time) float64 s; section (section) str
                      acc (time, section) m/s^2, vertical deck; nominal 50 Hz
    /truth (synthetic only)
                      time (time) float64 s; section; order (order) 0..3
                      U, A (time, section) m/s and m; r (time, section, order) m/s;
                      regime (time, section) int 1..4; optional coef
                      (equation, feature); optional coefficient curves
                      curves (equation, order, wind) m^(1-i)/s with
                      wind (wind) m/s (docs/concepts.md (coefficient curves)); optional slow changes
                      damping_ratio, mass_factor (time) and aero_factor
                      (time, order), dimensionless; optional attributes
                      config_json (vivbench's generator configuration) and tau.
                      Only time, section, U, A, r and regime are required
                      (regime may lack its units attribute, order its
                      coordinate), so truths written by other tools load;
                      identification never reads /truth.

Times are seconds since ``start_time`` and are authoritative: a gap in the
data is a run of NaN values, never a missing time. Section labels are
"S1".."Sn" in order (S1, S2, S3 at 1/4, 1/2, 3/4 of the main span by default)
and are the same in every group.

Accepted spellings of units (exact strings): "m/s" or "m s-1"; "m/s^2",
"m s-2" or "m/s2"; "s"; "m"; "1". Files that break the layout are refused with
:class:`EventFormatError`, whose one-line message starts with the file name.
"""

from __future__ import annotations

import json
import math
import numbers
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path

import h5py
import numpy as np
import xarray as xr

from vivbench.io.netcdf import NETCDF_ENGINE, write_netcdf_atomic
from vivbench.core.errors import InputError

__all__ = ["EventFormatError", "FORMAT", "FORMAT_VERSION", "NOMINAL_RATES", "COEF_UNITS", "build_event", "validate_event", "write_event", "read_event", "event_arrays", "list_events",
           "EventSummary", "read_event_summary", "peek_event_id"]

FORMAT = "vivbench-event"
FORMAT_VERSION = 1
#: Nominal sampling rates (Hz) of the sensor groups; a file may deviate by 10 %.
NOMINAL_RATES = {"wind": 32.0, "accel": 50.0}
#: Units of the exact coefficient matrix: column (i, j) multiplies A^i U^j.
COEF_UNITS = "1/s * m^(1-i) (m/s)^(-j)"
#: Units of coefficient curves a_ki(U): the coefficient of A^i in dA/dt (m/s).
CURVE_UNITS = "m^(1-order) s-1"

_RATE_TOLERANCE = 0.10
_SOURCES = ("synthetic", "field")
_ROOT_ATTRS = ("format", "format_version", "event_id", "start_time", "source", "span_azimuth_deg")
_EVENT_ID = re.compile(r"[A-Za-z0-9_-]+")
_UNIT_SPELLINGS = {
    "m/s": ("m/s", "m s-1"),
    "m/s^2": ("m/s^2", "m s-2", "m/s2"),
    "s": ("s",),
    "m": ("m",),
    "1": ("1",),
}
_TRUTH_KEYS = ("time", "U", "A", "r", "regime", "config", "coef", "feature", "tau",
               "damping_ratio", "mass_factor", "aero_factor", "curves", "wind")
#: Optional /truth variables of the generator's slow changes (docs/concepts.md (no inverse crime)): name -> (dims, long_name).
_CHANGE_VARS = {
    "damping_ratio": (("time",), "structural damping ratio zeta of the mode"),
    "mass_factor": (("time",), "mass per unit length relative to the configured structure"),
    "aero_factor": (("time", "order"), "factor of the aerodynamic part of the order-i terms relative to the configured aerodynamics"),
}


class EventFormatError(InputError):
    """An event file (or in-memory event) that breaks the format of docs/formats.md.

    Parameters
    ----------
    filename : str
        Name of the file (or a label such as ``"<memory>"``); the message
        starts with it.
    problem : str
        What is wrong; newlines are folded so that the message is one line.
    """

    def __init__(self, filename: str, problem: str):
        self.filename = str(filename)
        self.problem = " ".join(str(problem).split())
        super().__init__(f"{self.filename}: {self.problem}")

    def __reduce__(self):
        # Rebuild from both parts so the error survives pickling (worker processes).
        return (type(self), (self.filename, self.problem))


# --------------------------------------------------------------------------- build


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
    given = [k for k in _CHANGE_VARS if truth.get(k) is not None]
    if given and len(given) != len(_CHANGE_VARS):
        raise ValueError(f"truth has {given} but the slow changes need all of {list(_CHANGE_VARS)}")
    for name in given:
        dims, long_name = _CHANGE_VARS[name]
        shape = (n_t,) if dims == ("time",) else (n_t, 4)
        values = _as_float(truth[name], f"truth[{name!r}]", shape, "(n_t,)" if dims == ("time",) else "(n_t, 4)")
        ds[name] = (dims, values.astype(np.float64), {"units": "1", "long_name": long_name})
    return ds


# ------------------------------------------------------------------------ validate


def validate_event(tree: xr.DataTree, name: str = "<memory>") -> None:
    """Check an event against the format; raise on the first breach.

    Parameters
    ----------
    tree : xarray.DataTree
        The event.
    name : str
        File name (or label) that starts the error message.

    Raises
    ------
    EventFormatError
        One-line message naming ``name`` and the problem.
    """
    try:
        _validate(tree)
    except _Breach as breach:
        raise EventFormatError(name, str(breach)) from None
    except (TypeError, ValueError, KeyError, AttributeError, IndexError) as exc:
        # Content of a kind no check anticipated (say an attribute stored as an
        # array) is still a breach of the format, not a crash.
        raise EventFormatError(name, f"malformed content ({type(exc).__name__}: {exc})") from exc


class _Breach(Exception):
    """Internal: a format breach, turned into EventFormatError with the file name."""


def _validate(tree) -> None:
    if not isinstance(tree, xr.DataTree):
        raise _Breach(f"expected an xarray.DataTree, got {type(tree).__name__}")
    _check_root_attrs(tree.attrs)
    groups = {}
    for group in ("wind", "accel"):
        if group not in tree.children:
            raise _Breach(f"missing group /{group}")
        groups[group] = tree.children[group].to_dataset()

    sections = None
    for group, variables in (("wind", ("u", "v", "w")), ("accel", ("acc",))):
        ds = groups[group]
        _check_time(ds, group, NOMINAL_RATES[group])
        sections = _check_sections(ds, group, "section", sections)
        unit = "m/s" if group == "wind" else "m/s^2"
        for var in variables:
            _check_variable(ds, group, var, ("time", "section"), unit)

    if "truth" in tree.children:
        _check_truth(tree.children["truth"].to_dataset(), sections)


def _check_root_attrs(attrs) -> None:
    missing = [k for k in _ROOT_ATTRS if k not in attrs]
    if missing:
        raise _Breach(f"missing root attribute {', '.join(missing)}")
    for key in ("format", "event_id", "start_time", "source"):
        if not isinstance(attrs[key], str):
            raise _Breach(f"root attribute {key} is {attrs[key]!r}, expected a string")
    if attrs["format"] != FORMAT:
        raise _Breach(f"root attribute format is {attrs['format']!r}, expected {FORMAT!r}")
    version = attrs["format_version"]
    if not isinstance(version, numbers.Integral) or isinstance(version, (bool, np.bool_)):
        raise _Breach(f"root attribute format_version is {version!r}, expected the integer {FORMAT_VERSION}")
    if version > FORMAT_VERSION:
        raise _Breach(f"format_version {version} is not supported: it is newer than this vivbench reads "
                      f"(up to version {FORMAT_VERSION}); upgrade vivbench")
    if version != FORMAT_VERSION:
        raise _Breach(f"format_version {version} is not supported; this reader knows version {FORMAT_VERSION}")
    event_id = attrs["event_id"]
    if not _EVENT_ID.fullmatch(event_id):
        raise _Breach(f"event_id {event_id!r} must be a non-empty str of letters, digits, '_' and '-'")
    _parse_utc(attrs["start_time"])
    if attrs["source"] not in _SOURCES:
        raise _Breach(f"source {attrs['source']!r} is not one of {', '.join(_SOURCES)}")
    az = attrs["span_azimuth_deg"]
    if not isinstance(az, numbers.Real) or isinstance(az, (bool, np.bool_)) or not math.isfinite(az):
        raise _Breach(f"span_azimuth_deg {az!r} must be a finite number of degrees")


def _parse_utc(text: str) -> datetime:
    # Python < 3.11 does not read the "Z" suffix.
    candidate = text[:-1] + "+00:00" if text.endswith(("Z", "z")) else text
    try:
        moment = datetime.fromisoformat(candidate)
    except ValueError:
        raise _Breach(f"start_time {text!r} is not an ISO 8601 date and time") from None
    if moment.tzinfo is None or moment.utcoffset() != timedelta(0):
        raise _Breach(f"start_time {text!r} must be in UTC: end it with 'Z' or '+00:00'")
    return moment


def _check_units(var: xr.DataArray, where: str, expected: str) -> None:
    spellings = _UNIT_SPELLINGS[expected]
    allowed = " or ".join(repr(s) for s in spellings)
    if "units" not in var.attrs:
        raise _Breach(f"{where} has no units attribute, expected {allowed}")
    if not isinstance(var.attrs["units"], str) or var.attrs["units"] not in spellings:
        raise _Breach(f"{where} has units {var.attrs['units']!r}, expected {allowed}")


def _check_time(ds: xr.Dataset, group: str, nominal: float | None) -> None:
    where = f"/{group}/time"
    if "time" not in ds.coords:
        raise _Breach(f"missing coordinate {where}")
    t = ds.coords["time"]
    if t.dims != ("time",):
        raise _Breach(f"{where} has dimensions {t.dims}, expected ('time',)")
    if t.dtype != np.float64:
        raise _Breach(f"{where} has dtype {t.dtype}, expected float64")
    _check_units(t, where, "s")
    values = t.values
    if values.size < 2:
        raise _Breach(f"{where} has {values.size} sample(s), at least 2 needed")
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise _Breach(
            f"{where}[{bad[0]}] is {float(values[bad[0]])}; every time must be given (a data gap is NaN values, not NaN times)"
        )
    step = np.diff(values)
    bad = np.flatnonzero(step <= 0)
    if bad.size:
        i = bad[0] + 1
        if step[bad[0]] == 0:
            raise _Breach(f"{where} is not strictly increasing: t = {float(values[i])!r} s repeats at index {i}")
        raise _Breach(
            f"{where} is not strictly increasing: it goes back from {float(values[i - 1])!r} s"
            f" to {float(values[i])!r} s at index {i}"
        )
    if nominal is not None:
        rate = 1.0 / np.median(step)
        if abs(rate / nominal - 1.0) > _RATE_TOLERANCE:
            raise _Breach(
                f"{where}: sampling rate {rate:.4g} Hz (median step) is more than "
                f"{_RATE_TOLERANCE:.0%} from the nominal {nominal:g} Hz"
            )


def _check_sections(ds: xr.Dataset, group: str, coord: str, expected: tuple | None) -> tuple:
    where = f"/{group}/{coord}"
    if coord not in ds.coords:
        raise _Breach(f"missing coordinate {where}")
    c = ds.coords[coord]
    if c.dims != (coord,):
        raise _Breach(f"{where} has dimensions {c.dims}, expected ({coord!r},)")
    labels = tuple(c.values.tolist())
    if not all(isinstance(s, str) for s in labels):
        raise _Breach(f"{where} must hold strings; got dtype {c.dtype}")
    if expected is None:
        wanted = tuple(f"S{k + 1}" for k in range(len(labels)))
        if not labels or labels != wanted:
            raise _Breach(f"{where} labels are {list(labels)}, expected 'S1'..'Sn' in order, e.g. ['S1', 'S2', 'S3']")
    elif labels != expected:
        raise _Breach(f"{where} labels are {list(labels)}, expected {list(expected)} as in /wind/section")
    return labels


def _check_variable(ds: xr.Dataset, group: str, var: str, dims: tuple, unit: str | None, kind: str = "f") -> xr.DataArray:
    where = f"/{group}/{var}"
    if var not in ds.data_vars:
        raise _Breach(f"missing variable {where}")
    da = ds[var]
    if da.dims != dims:
        raise _Breach(f"{where} has dimensions {da.dims}, expected {dims}")
    if da.dtype.kind not in kind:
        wanted = "floating point" if kind == "f" else "integer"
        raise _Breach(f"{where} has dtype {da.dtype}, expected {wanted}")
    if unit is not None:
        _check_units(da, where, unit)
    return da


def _check_truth(ds: xr.Dataset, sections: tuple) -> None:
    _check_time(ds, "truth", None)
    _check_sections(ds, "truth", "section", sections)
    # Only what validation uses is required (time, section, U, A, r, regime); the rest is
    # optional and checked when present, so that truths written by other tools load.
    if "order" in ds.coords:
        order = ds.coords["order"]
        if order.dims != ("order",) or order.dtype.kind not in "iuf" or order.values.tolist() != [0, 1, 2, 3]:
            raise _Breach(f"/truth/order is {order.values.tolist()}, expected [0, 1, 2, 3]")
    elif ds.sizes.get("order", 4) != 4:
        # Without a coordinate the dimension is read as the orders 0..3 of docs/formats.md.
        raise _Breach(f"/truth has {ds.sizes['order']} orders, expected 4 (0..3)")
    _check_variable(ds, "truth", "U", ("time", "section"), "m/s")
    _check_variable(ds, "truth", "A", ("time", "section"), "m")
    _check_variable(ds, "truth", "r", ("time", "section", "order"), "m/s")
    # A regime is dimensionless: a missing units attribute is read as "1" (CF convention).
    if "regime" not in ds.data_vars:
        raise _Breach("missing variable /truth/regime")
    regime_units = "1" if "units" in ds["regime"].attrs else None
    regime = _check_variable(ds, "truth", "regime", ("time", "section"), regime_units, kind="iu").values
    outside = (regime < 1) | (regime > 4)
    if outside.any():
        raise _Breach(f"/truth/regime has values {sorted(set(regime[outside].tolist()))[:5]} outside 1..4")
    # The generator configuration is vivbench's own (config_json); another generator may keep
    # its configuration under another name or none: whatever needs it is then unavailable.
    if "config_json" in ds.attrs:
        if not isinstance(ds.attrs["config_json"], str):
            raise _Breach("/truth attribute config_json must be a JSON string")
        try:
            json.loads(ds.attrs["config_json"])
        except (TypeError, ValueError) as exc:
            raise _Breach(f"/truth attribute config_json is not valid JSON ({exc})") from None
    if "tau" in ds.attrs:
        tau = ds.attrs["tau"]
        if not isinstance(tau, numbers.Real) or isinstance(tau, (bool, np.bool_)) or not 0.0 < tau < 1.0:
            raise _Breach(f"/truth attribute tau is {tau!r}, expected a number strictly between 0 and 1")
    if "coef" in ds.data_vars:
        coef = _check_variable(ds, "truth", "coef", ("equation", "feature"), None)
        if not isinstance(coef.attrs.get("units"), str) or coef.attrs["units"] != COEF_UNITS:
            raise _Breach(f"/truth/coef has units {coef.attrs.get('units')!r}, expected {COEF_UNITS!r}")
        _check_sections(ds, "truth", "equation", sections)
        if "feature" not in ds.coords:
            raise _Breach("missing coordinate /truth/feature")
        names = ds.coords["feature"].values.tolist()
        if not all(isinstance(f, str) and f for f in names) or len(set(names)) != len(names):
            raise _Breach("/truth/feature must hold distinct non-empty strings")
    elif "feature" in ds.coords:
        raise _Breach("/truth has a feature coordinate but no coef variable")
    if "curves" in ds.data_vars:
        _check_truth_curves(ds, sections)
    elif "wind" in ds.coords:
        raise _Breach("/truth has a wind coordinate but no curves variable")
    if "equation" in ds.coords and "coef" not in ds.data_vars and "curves" not in ds.data_vars:
        raise _Breach("/truth has an equation coordinate but neither coef nor curves")
    present = [k for k in _CHANGE_VARS if k in ds.data_vars]
    if present and len(present) != len(_CHANGE_VARS):
        raise _Breach(f"/truth has {present} but the slow changes need all of {list(_CHANGE_VARS)}")
    for name in present:
        values = _check_variable(ds, "truth", name, _CHANGE_VARS[name][0], "1").values
        if not np.all(np.isfinite(values)) or np.any(values < 0):
            raise _Breach(f"/truth/{name} must be finite and >= 0")


def _check_truth_curves(ds: xr.Dataset, sections: tuple) -> None:
    """The optional exact coefficient curves of /truth (docs/concepts.md (coefficient curves))."""
    curves = _check_variable(ds, "truth", "curves", ("equation", "order", "wind"), None)
    if curves.attrs.get("units") != CURVE_UNITS:
        raise _Breach(f"/truth/curves has units {curves.attrs.get('units')!r}, expected {CURVE_UNITS!r}")
    _check_sections(ds, "truth", "equation", sections)
    if "wind" not in ds.coords:
        raise _Breach("missing coordinate /truth/wind (m/s) of /truth/curves")
    wind = ds.coords["wind"]
    if wind.dims != ("wind",) or wind.dtype.kind != "f":
        raise _Breach(f"/truth/wind must be a 1-D floating-point coordinate; got dims {wind.dims}, dtype {wind.dtype}")
    _check_units(wind, "/truth/wind", "m/s")
    w = wind.values
    if w.size < 2 or not np.all(np.isfinite(w)) or np.any(w <= 0) or np.any(np.diff(w) <= 0):
        raise _Breach("/truth/wind must hold at least 2 finite positive increasing speeds")


# -------------------------------------------------------------------- write / read


def write_event(tree: xr.DataTree, path) -> Path:
    """Validate an event and write it atomically.

    The file is first written to a hidden temporary file in the target
    directory (``.<name>.tmp-<pid>-<random>``, which a glob for ``*.nc`` never
    matches), flushed to disk, then renamed over ``path``. On any failure the
    temporary file is removed and an existing file at ``path`` is untouched.

    Parameters
    ----------
    tree : xarray.DataTree
        The event (see :func:`build_event`).
    path : str or os.PathLike
        Destination; missing parent directories are created.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    EventFormatError
        If the tree breaks the format (nothing is written).
    """
    path = Path(path)
    validate_event(tree, name=str(path))
    return write_netcdf_atomic(tree, path)


def read_event(path, *, truth: bool = True) -> xr.DataTree:
    """Read an event file fully into memory, close it and validate it.

    Parameters
    ----------
    path : str or os.PathLike
    truth : bool
        False: the ``/truth`` group is neither read nor checked and the
        returned tree has none. Identification reads events so: it never uses
        the truth, and a truth that is absent, partial or written by another
        generator does not stop it.

    Returns
    -------
    xarray.DataTree
        In-memory event (no file handle stays open); variable encodings are
        dropped so that a re-write uses this module's settings.

    Raises
    ------
    EventFormatError
        Missing file, not NetCDF-4/HDF5, unreadable layout, or any breach of
        the format; the message starts with the file name.
    """
    path = Path(path)
    name = str(path)
    if not path.exists():
        raise EventFormatError(name, "no such file")
    if path.is_dir():
        raise EventFormatError(name, "is a directory, not an event file")
    try:
        _check_stored_shapes(path, skip=() if truth else ("/truth",))
        if truth:
            tree = xr.load_datatree(path, engine=NETCDF_ENGINE, decode_times=False, decode_timedelta=False)
        else:
            with xr.open_datatree(path, engine=NETCDF_ENGINE, decode_times=False, decode_timedelta=False) as lazy:
                tree = xr.DataTree.from_dict(
                    {node.path: node.to_dataset(inherit=False) for node in lazy.subtree
                     if node.path != "/truth" and not node.path.startswith("/truth/")}).load()
    except _Breach as breach:
        raise EventFormatError(name, str(breach)) from None
    except Exception as exc:  # noqa: BLE001 - any reader failure means "not an event file"
        raise EventFormatError(name, f"cannot be read as NetCDF-4/HDF5 ({type(exc).__name__}: {exc})") from exc
    for node in tree.subtree:
        for var in node.variables.values():
            var.encoding = {}
    validate_event(tree, name=name)
    return tree


def _check_stored_shapes(path: Path, skip: tuple = ()) -> None:
    """Compare each stored array with the lengths of its dimensions.

    The netCDF layer silently pads an array shorter than its dimension (with
    zeros when it has no fill value) and never reports the mismatch, so the
    HDF5 shapes are checked directly against the dimension scales.
    """
    with h5py.File(path, "r") as f:
        datasets = []
        f.visititems(lambda _, obj: datasets.append(obj) if isinstance(obj, h5py.Dataset) else None)
        for ds in datasets:
            if any(ds.name == g or ds.name.startswith(g + "/") for g in skip):
                continue
            for axis, dim in enumerate(ds.dims):
                if len(dim) == 0:
                    continue
                scale = dim[0]
                if scale.name == ds.name or scale.ndim != 1:
                    continue
                if scale.shape[0] != ds.shape[axis]:
                    raise _Breach(
                        f"{ds.name} has shape {ds.shape}: {ds.shape[axis]} entries along "
                        f"{scale.name.rsplit('/', 1)[-1]}, but {scale.name} has {scale.shape[0]}"
                    )


@dataclass(frozen=True)
class EventSummary:
    """The small parts of an event file, read without its sensor records.

    Attributes
    ----------
    path : pathlib.Path
        The file.
    attrs : dict
        Root attributes (format, format_version, event_id, start_time, source,
        span_azimuth_deg and any extra ones).
    truth : xarray.Dataset or None
        The ``/truth`` group in memory (synthetic events), None for field events.
    accel_time : numpy.ndarray, shape (n_acc,), s
        Accelerometer times since ``start_time``.
    """

    path: Path
    attrs: dict
    truth: xr.Dataset | None
    accel_time: np.ndarray

    @property
    def duration_s(self) -> float:
        """Span of the accelerometer record, s (0 when it is empty)."""
        t = self.accel_time
        return float(t[-1] - t[0]) if t.size else 0.0


def read_event_summary(path) -> EventSummary:
    """Read an event's root attributes, ``/truth`` and accelerometer times, not its sensor records.

    The root attributes are checked (format, a supported ``format_version``,
    event_id, start_time, source, span azimuth); the groups are not validated
    as :func:`read_event` does. The 32 Hz wind and 50 Hz acceleration values
    stay on disk, which makes this cheap for reports over many events.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    EventSummary

    Raises
    ------
    EventFormatError
        Missing or unreadable file, another format, a newer format_version or
        a broken root attribute; the message starts with the file name.
    """
    path = Path(path)
    name = str(path)
    if not path.is_file():
        raise EventFormatError(name, "no such event file")
    try:
        with xr.open_datatree(path, engine=NETCDF_ENGINE, decode_times=False, decode_timedelta=False) as tree:
            attrs = dict(tree.attrs)
            _check_root_attrs(attrs)
            truth = tree["truth"].to_dataset().load() if "truth" in tree.children else None
            if "accel" not in tree.children:
                raise _Breach("missing group /accel")
            accel_time = np.asarray(tree["accel"]["time"].values)
    except _Breach as breach:
        raise EventFormatError(name, str(breach)) from None
    except Exception as exc:  # noqa: BLE001 - any reader failure means "not an event file"
        raise EventFormatError(name, f"cannot be read as NetCDF-4/HDF5 ({type(exc).__name__}: {exc})") from exc
    return EventSummary(path=path, attrs=attrs, truth=truth, accel_time=accel_time)


def peek_event_id(path) -> str | None:
    """The root attribute ``event_id`` of an event file, read cheaply (HDF5 attributes only).

    Nothing is validated: use it to plan work (say, to find two files with one
    id), then :func:`read_event` to read.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    str or None
        None when the file cannot be opened or has no string ``event_id``
        (:func:`read_event` then says why).
    """
    try:
        with h5py.File(path, "r") as f:
            eid = f.attrs.get("event_id")
    except Exception:  # noqa: BLE001 - any failure is reported by read_event later
        return None
    if isinstance(eid, bytes):
        eid = eid.decode("utf-8", "replace")
    return eid if isinstance(eid, str) else None


# ------------------------------------------------------------------------- helpers


def event_arrays(tree: xr.DataTree, *, truth: bool = True) -> dict:
    """The event's data as plain numpy arrays (no copies where avoidable).

    Parameters
    ----------
    tree : xarray.DataTree
        A valid event.
    truth : bool
        False: leave ``/truth`` alone (identification never reads it).

    Returns
    -------
    dict
        ``sections`` (tuple of str); ``wind_time`` (n_wind,) s; ``u``, ``v``,
        ``w`` (n_wind, n_sec) m/s; ``accel_time`` (n_acc,) s; ``acc``
        (n_acc, n_sec) m/s^2; and, if the event has a truth,
        ``truth_time`` (n_t,) s; ``U`` (n_t, n_sec) m/s; ``A`` (n_t, n_sec) m;
        ``r`` (n_t, n_sec, 4) m/s; ``regime`` (n_t, n_sec) int; plus ``coef``
        (n_sec, n_features) and ``feature`` (tuple of str) when stored, the
        slow changes ``damping_ratio``, ``mass_factor`` (n_t,) and ``aero_factor``
        (n_t, 4), dimensionless, when stored, and the coefficient curves
        ``curves`` (n_sec, 4, n_wind) m^(1-i)/s with ``curve_wind`` (n_wind,)
        m/s when stored.
    """
    wind = tree["wind"]
    accel = tree["accel"]
    out = {
        "sections": tuple(wind["section"].values.tolist()),
        "wind_time": wind["time"].values,
        "u": wind["u"].values,
        "v": wind["v"].values,
        "w": wind["w"].values,
        "accel_time": accel["time"].values,
        "acc": accel["acc"].values,
    }
    if truth and "truth" in tree.children:
        group = tree["truth"]
        out.update(
            truth_time=group["time"].values,
            U=group["U"].values,
            A=group["A"].values,
            r=group["r"].values,
            regime=group["regime"].values,
        )
        if "coef" in group.data_vars:
            out["coef"] = group["coef"].values
            out["feature"] = tuple(group["feature"].values.tolist())
        for name in _CHANGE_VARS:
            if name in group.data_vars:
                out[name] = group[name].values
        if "curves" in group.data_vars:
            out["curves"] = group["curves"].values
            out["curve_wind"] = group["wind"].values
    return out


def list_events(directory) -> list[Path]:
    """Event files in a directory, sorted by name.

    Event files are named ``<event_id>.nc`` (event ids have no dots); result
    files such as ``<event_id>.identify.nc``, hidden and temporary files and
    sub-directories are left out.

    Parameters
    ----------
    directory : str or os.PathLike

    Returns
    -------
    list of pathlib.Path

    Raises
    ------
    FileNotFoundError, NotADirectoryError
    """
    directory = Path(directory)
    if not directory.exists():
        raise FileNotFoundError(f"{directory}: no such directory")
    if not directory.is_dir():
        raise NotADirectoryError(f"{directory}: not a directory")
    return sorted(
        p for p in directory.glob("*.nc") if p.is_file() and _EVENT_ID.fullmatch(p.name[: -len(".nc")])
    )
