"""The event file format (docs/formats.md): its constants, its error and the check of one event in memory.

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
from datetime import datetime, timedelta

import numpy as np
import xarray as xr

from vivbench.core.errors import InputError

__all__ = ["EventFormatError", "FORMAT", "FORMAT_VERSION", "NOMINAL_RATES", "COEF_UNITS", "CURVE_UNITS",
           "CHANGE_VARIABLES", "EVENT_ID_PATTERN", "validate_event", "validate_root_attributes"]

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
#: What an event_id (and so an event file's stem) may hold.
EVENT_ID_PATTERN = re.compile(r"[A-Za-z0-9_-]+")
_UNIT_SPELLINGS = {
    "m/s": ("m/s", "m s-1"),
    "m/s^2": ("m/s^2", "m s-2", "m/s2"),
    "s": ("s",),
    "m": ("m",),
    "1": ("1",),
    "degree": ("degree", "degrees", "deg"),
}
#: long_name of the optional /truth/yaw (degree): the yaw the averaged truth's aerodynamics see, unsigned (they
#: depend on its magnitude only; the measured yaw of a result is signed).
TRUTH_YAW_NAME = "yaw of the mean wind the averaged truth sees: unsigned angle to the span's normal"

#: Optional /truth variables of the generator's slow changes (docs/concepts.md (no inverse crime)): name -> (dims, long_name).
CHANGE_VARIABLES = {
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


def validate_root_attributes(attrs, name: str = "<memory>") -> None:
    """Check an event's root attributes only (format, version, event_id, start_time, source, span azimuth).

    Parameters
    ----------
    attrs : mapping
        The root attributes.
    name : str
        File name (or label) that starts the error message.

    Raises
    ------
    EventFormatError
        One-line message naming ``name`` and the first broken attribute.
    """
    try:
        _check_root_attrs(attrs)
    except _Breach as breach:
        raise EventFormatError(name, str(breach)) from None


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
    if not EVENT_ID_PATTERN.fullmatch(event_id):
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
    if "yaw" in ds.data_vars:
        yaw = _check_variable(ds, "truth", "yaw", ("time", "section"), "degree").values
        if not np.all(np.isfinite(yaw)) or np.any(np.abs(yaw) > 90.0):
            raise _Breach("/truth/yaw must hold finite angles within [-90, 90] degrees")
    present = [k for k in CHANGE_VARIABLES if k in ds.data_vars]
    if present and len(present) != len(CHANGE_VARIABLES):
        raise _Breach(f"/truth has {present} but the slow changes need all of {list(CHANGE_VARIABLES)}")
    for name in present:
        values = _check_variable(ds, "truth", name, CHANGE_VARIABLES[name][0], "1").values
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
