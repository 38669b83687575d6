"""Field data import: CSV and MATLAB files to the event format (docs/formats.md).

A mapping file (TOML) says where each channel is and in which unit::

    event_id = "F001"
    start_time = "2026-01-01T00:00:00Z"   # optional when the times are ISO 8601
    span_azimuth_deg = 30.0

    [wind]                       # defaults for every wind channel
    time = "time"                # time column (CSV) or variable (MAT)
    time_format = "seconds"      # "seconds" since start_time, or "iso8601"
    units = "m/s"                # m/s, km/h, knots

    [wind.S1]                    # one table per section, S1..Sn in order
    file = "wind_S1.csv"         # paths are relative to the mapping file
    u = "u"                      # column names
    v = "v"
    w = "w"

    [accel]
    file = "accel.csv"
    time = "time"
    units = "g"                  # m/s^2, g, mm/s^2, mg (milli-g)

    [accel.S1]
    acc = "acc_S1"

A channel is a column name or an inline table ``{column = "...", file = ...,
units = ..., time = ..., time_format = ..., rate = ..., index = k}``
(``index``: 1-based column of a MATLAB matrix); a setting of the channel
overrides its section's, which overrides its group's. ``file`` may be a glob
pattern or a list: the files are concatenated in time order.

Without positions, every section S1..Sn needs ``u``, ``v``, ``w`` and
``acc``, and the wind and acceleration sections are the same. With
``span_length_m`` at the root and ``position_m`` in every wind and
acceleration table, the wind tables are anemometers (any names, any number
>= 1) and each section's wind comes from them by ``wind_rule`` (``nearest``
or ``interpolation``, :mod:`vivbench.io.field_wind`); an anemometer reports
``format = "enu"`` (u, v, w), ``"instrument"`` (u, v, w in its frame, with
``heading_deg``) or ``"speed_direction"`` (speed, direction, optional w).
Records at other rates than the event grid's are resampled onto it
(:mod:`vivbench.io.field_resample`). docs/field_import.md has the full syntax.

Sources: CSV with a header row (empty cells and NaN are missing values); MAT
files v4-v7 (:func:`scipy.io.loadmat`) and v7.3 (HDF5, read with h5py).
ISO 8601 times (with their offset; none means UTC) are read from CSV only.

Repairs, counted in root attributes of the event (``quality_*``): rows out of
time order (at most 1 % of a file) are sorted; rows that repeat a time stamp
are dropped (the first is kept); files of one group whose time stamps differ
are merged on the union of their times, each channel NaN where its file has no
row. Refused with a one-line :class:`~vivbench.core.errors.InputError` naming
the file: a mapping error (a position outside the span among them), a missing
file, column or variable, a cell that is not a number, a missing time, a clock
that goes back more often, an implausible rate or one that contradicts the
declared rate, files that overlap in time, files of one group whose clocks do
not line up, and magnitudes that betray a wrong unit (see
:mod:`vivbench.io.quality`). Unit conversions are recorded as
``import_units_<var>_<sensor>`` (the declared unit) and
``import_factor_<var>_<sensor>`` (the factor to SI).
"""

from __future__ import annotations

import glob
import math
import warnings
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import h5py
import numpy as np
import pandas as pd

from vivbench.io.event import NOMINAL_RATES, EventFormatError, build_event, write_event
from vivbench.io.field_wind import WIND_FORMATS, WIND_RULES, span_weights, to_east_north_up
from vivbench.io.field_resample import FIELD_RATE_TOLERANCE, measured_rate, regular_grid, resample_to_grid
from vivbench.io.quality import ACC_UNITS, WIND_UNITS, check_acc_magnitude, check_wind_magnitude
from vivbench.core.errors import InputError

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib

__all__ = ["import_event", "load_mapping", "TIME_FORMATS"]

TIME_FORMATS = ("seconds", "iso8601")
_GROUPS = ("wind", "accel")
_UNITS = {"wind": WIND_UNITS, "accel": ACC_UNITS}
_SETTINGS = ("file", "time", "time_format", "units", "rate")
_ROOT_KEYS = ("event_id", "start_time", "span_azimuth_deg", "source", "span_length_m", "wind_rule", "wind", "accel")
# Settings of the wind group or an anemometer (not of a channel).
_WIND_KEYS = ("format", "heading_deg")
# Sorting is a repair for a few swapped rows; a clock that goes back more often is refused.
_MAX_REORDER_FRACTION = 0.01


@dataclass(frozen=True)
class _Source:
    """The files of one source: one, or several to concatenate in time order."""

    paths: tuple

    def __str__(self) -> str:
        first = str(self.paths[0])
        return first if len(self.paths) == 1 else f"{first} (and {len(self.paths) - 1} more files)"


@dataclass(frozen=True)
class _Channel:
    group: str
    var: str
    section: str
    file: _Source
    column: str
    time: str
    time_format: str
    units: str
    index: int | None
    rate: float | None


# --------------------------------------------------------------------- mapping


def load_mapping(path) -> dict:
    """Read and check a mapping file.

    Parameters
    ----------
    path : str or os.PathLike
        TOML mapping (see the module docstring).

    Returns
    -------
    dict
        ``event_id``, ``start_time`` (str or None), ``span_azimuth_deg``,
        ``source``, ``sections`` (list of str) and ``channels`` (list of
        resolved channel descriptions).

    Raises
    ------
    ValueError
        One line starting with the mapping file's name.
    """
    path = Path(path)
    name = str(path)
    if not path.is_file():
        raise InputError(f"{name}: no such mapping file")
    try:
        with open(path, "rb") as fh:
            raw = tomllib.load(fh)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{name}: not valid TOML ({exc})") from None

    def bad(problem: str) -> InputError:
        return InputError(f"{name}: {' '.join(problem.split())}")

    unknown = sorted(set(raw) - set(_ROOT_KEYS))
    if unknown:
        raise bad(f"unknown key(s) {unknown}; allowed: {list(_ROOT_KEYS)}")
    for key in ("event_id", "span_azimuth_deg", "wind", "accel"):
        if key not in raw:
            raise bad(f"missing {key!r}; a mapping needs event_id, span_azimuth_deg, [wind] and [accel]")
    if not isinstance(raw["event_id"], str):
        raise bad(f"event_id must be a string; got {raw['event_id']!r}")
    az = raw["span_azimuth_deg"]
    if isinstance(az, bool) or not isinstance(az, (int, float)) or not math.isfinite(az):
        raise bad(f"span_azimuth_deg must be a finite number of degrees; got {az!r}")
    start = raw.get("start_time")
    if isinstance(start, datetime):  # TOML has a date-time type; keep it as text
        if start.tzinfo is None:
            raise bad("start_time needs an offset: end it with Z (UTC)")
        start = start.astimezone(timezone.utc).isoformat().replace("+00:00", "Z")
    if start is not None and not isinstance(start, str):
        raise bad(f"start_time must be an ISO 8601 string such as \"2026-01-01T00:00:00Z\"; got {start!r}")
    source = raw.get("source", "field")

    positioned = "span_length_m" in raw or any(
        isinstance(raw[g], dict) and any(isinstance(t, dict) and "position_m" in t for t in raw[g].values())
        for g in _GROUPS)
    span = _number(raw, "span_length_m", "the span's length in m", bad, required=positioned, positive=True)
    rule = raw.get("wind_rule", "nearest")
    if rule not in WIND_RULES:
        raise bad(f"wind_rule {rule!r} is not one of {', '.join(WIND_RULES)}")
    channels: list[_Channel] = []
    sections_of, tables_of = {}, {}
    for group in _GROUPS:
        table = raw[group]
        if not isinstance(table, dict):
            raise bad(f"[{group}] must be a table")
        group_keys = _SETTINGS + (_WIND_KEYS if group == "wind" else ())
        sec_names = [k for k in table if k not in group_keys]
        wrong = [k for k in sec_names if not isinstance(table[k], dict)]
        if wrong:
            raise bad(f"unknown key(s) {wrong} in [{group}]; allowed: {list(group_keys)} and sensor tables")
        expected = [f"S{k + 1}" for k in range(len(sec_names))]
        if group == "wind" and positioned:
            expected = sec_names  # anemometers: any names when positions are declared
        elif sorted(sec_names, key=_section_order) != expected:
            sec_names = []
        if not sec_names:
            raise bad(f"[{group}] has sections {sec_names}; expected tables S1..Sn, e.g. [{group}.S1], [{group}.S2], [{group}.S3]")
        sections_of[group] = expected
        base = {k: table[k] for k in group_keys if k in table}
        for sec in expected:
            st = table[sec]
            level = {**base, **{k: st[k] for k in group_keys if k in st}}
            where = f"[{group}.{sec}]"
            info = {"name": sec, "position_m": None}
            if positioned:
                pos = _number(st, "position_m", "its position along the span in m", bad, required=True, where=where)
                if not 0.0 <= pos <= span:
                    raise bad(f"{where} position_m = {pos:g} m is outside the span (0 to span_length_m = {span:g} m)")
                info["position_m"] = pos
            if group == "wind":
                fmt = level.get("format", "enu")
                if fmt not in WIND_FORMATS:
                    raise bad(f"{where} has format {fmt!r}; allowed: {', '.join(WIND_FORMATS)}")
                info["format"] = fmt
                info["heading_deg"] = _number(level, "heading_deg", "the instrument's x axis, degrees from north",
                                              bad, required=fmt == "instrument", where=where)
                required, optional = WIND_FORMATS[fmt]
            else:
                required, optional = ("acc",), ()
            extra = sorted(set(st) - set(group_keys) - {"position_m"} - set(required) - set(optional))
            if extra:
                raise bad(f"unknown key(s) {extra} in {where}; allowed: {list(required + optional)}, position_m "
                          f"and {list(group_keys)}")
            for var in required + tuple(v for v in optional if v in st):
                if var not in st:
                    raise bad(f"{where} lacks the channel {var!r}; every section needs {', '.join(required)}")
                channels.append(_resolve(path, group, sec, var, st[var], level, bad))
            tables_of.setdefault(group, []).append(info)
    if not positioned and sections_of["wind"] != sections_of["accel"]:
        raise bad(f"[wind] has sections {sections_of['wind']} but [accel] has {sections_of['accel']}; they must be "
                  f"the same, or declare span_length_m and position_m of every anemometer and section")
    return {
        "event_id": raw["event_id"],
        "start_time": start,
        "span_azimuth_deg": float(az),
        "source": source,
        "sections": sections_of["accel"],
        "anemometers": tables_of["wind"],
        "positions_m": [t["position_m"] for t in tables_of["accel"]] if positioned else None,
        "span_length_m": span,
        "wind_rule": rule,
        "channels": channels,
    }


def _number(table: dict, key: str, what: str, bad, *, required: bool, positive: bool = False, where: str = ""):
    """A finite number from a mapping table (None when absent and not required)."""
    if key not in table:
        if required:
            raise bad(f"{where or 'the mapping'} needs {key} ({what})".strip())
        return None
    x = table[key]
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or (positive and x <= 0):
        raise bad(f"{where} {key} must be a finite{' positive' if positive else ''} number ({what}); got {x!r}".strip())
    return float(x)


def _section_order(label: str):
    return (len(label), label)


def _resolve(mapping: Path, group: str, sec: str, var: str, spec, level: dict, bad) -> _Channel:
    where = f"[{group}.{sec}] {var}"
    if isinstance(spec, str):
        spec = {"column": spec}
    if not isinstance(spec, dict):
        raise bad(f"{where} must be a column name or a table {{column = ..., file = ..., units = ...}}; got {spec!r}")
    extra = sorted(set(spec) - {"column", "index", *_SETTINGS})
    if extra:
        raise bad(f"unknown key(s) {extra} in {where}; allowed: column, index, {', '.join(_SETTINGS)}")
    s = {**level, **{k: spec[k] for k in _SETTINGS if k in spec}}
    if "column" not in spec or not isinstance(spec["column"], str) or not spec["column"]:
        raise bad(f"{where} needs a column (name of the column or variable)")
    if "file" not in s:
        raise bad(f"{where} has no file: give file in [{group}], [{group}.{sec}] or the channel")
    units = "deg" if var == "direction" else s.get("units")
    allowed = ", ".join(_UNITS[group])
    if units is None:
        raise bad(f"{where} has no units: give units in [{group}] or below (one of {allowed})")
    if units not in _UNITS[group] and var != "direction":
        raise bad(f"{where} has units {units!r}; allowed for {group}: {allowed}")
    fmt = s.get("time_format", "seconds")
    if fmt not in TIME_FORMATS:
        raise bad(f"{where} has time_format {fmt!r}; allowed: {', '.join(TIME_FORMATS)}")
    time = s.get("time", "time")
    if not isinstance(time, str) or not time:
        raise bad(f"{where} has time {time!r}; expected the name of the time column or variable")
    index = spec.get("index")
    if index is not None and (isinstance(index, bool) or not isinstance(index, int) or index < 1):
        raise bad(f"{where} has index {index!r}; expected a 1-based column number of a MATLAB matrix")
    rate = s.get("rate")
    if rate is not None and (isinstance(rate, bool) or not isinstance(rate, (int, float)) or not rate > 0
                             or not math.isfinite(rate)):
        raise bad(f"{where} has rate {rate!r}; expected the sampling rate in Hz, a positive number")
    file = _Source(_expand_files(mapping, s["file"], where, bad))
    return _Channel(group, var, sec, file, spec["column"], time, fmt, units, index,
                    None if rate is None else float(rate))


def _expand_files(mapping: Path, spec, where: str, bad) -> tuple:
    """Paths of a ``file`` setting: a path, a glob pattern (``*``, ``?``, ``[``) or a list of either."""
    items = [spec] if isinstance(spec, str) else spec
    if not isinstance(items, list) or not items or not all(isinstance(x, str) and x for x in items):
        raise bad(f"{where} has file {spec!r}; expected a path, a glob pattern or a list of them")
    paths = []
    for item in items:
        full = item if Path(item).is_absolute() else str(mapping.parent / item)
        if any(ch in item for ch in "*?["):
            found = sorted(glob.glob(full))
            if not found:
                raise bad(f"{where}: the file pattern {item!r} matches no file")
            paths += [Path(f) for f in found]
        else:
            paths.append(Path(full))
    if len(set(paths)) != len(paths):
        raise bad(f"{where} names a file twice in {spec!r}")
    return tuple(paths)


# --------------------------------------------------------------------- sources


class _Table:
    """The files of one source, concatenated in time order; values read once."""

    def __init__(self, source: _Source):
        self.name = str(source)
        self.parts = [_File(p) for p in source.paths]
        self.order = list(range(len(self.parts)))

    def values(self, column: str, index: int | None = None) -> np.ndarray:
        return np.concatenate([self.parts[i].values(column, index) for i in self.order])

    def times(self, column: str, fmt: str) -> np.ndarray:
        """Times of the rows, the files put in the order of their first time; overlapping files are refused."""
        ts = [part.times(column, fmt) for part in self.parts]
        if len(ts) > 1:
            self.order = sorted(range(len(ts)), key=lambda i: ts[i].min())
            for a, b in zip(self.order, self.order[1:]):
                if ts[b].min() <= ts[a].max():
                    first, then = self.parts[a].name, self.parts[b].name
                    raise InputError(f"{first}, {then}: the files overlap in time ({Path(then).name} starts before "
                                     f"{Path(first).name} ends); "
                                     f"each instant must be in one file")
        return np.concatenate([ts[i] for i in self.order])


class _File:
    """One source file: columns or variables as float arrays, read once."""

    def __init__(self, path: Path):
        self.path = path
        self.name = str(path)
        if not path.is_file():
            raise InputError(f"{self.name}: no such data file")
        self.kind = "mat" if path.suffix.lower() == ".mat" else "csv"
        try:
            if self.kind == "csv":
                self._frame = pd.read_csv(path, skipinitialspace=True, comment="#", low_memory=False)
                self._frame.columns = [str(c).strip() for c in self._frame.columns]
                self.names = list(self._frame.columns)
            else:
                self._vars = _load_mat(path)
                self.names = sorted(self._vars)
        except ValueError:
            raise
        except Exception as exc:  # noqa: BLE001 - any reader failure: not a file of this kind
            raise InputError(f"{self.name}: cannot be read as {self.kind.upper()} ({type(exc).__name__}: {' '.join(str(exc).split())})") from None

    def _missing(self, column: str) -> InputError:
        kind = "column" if self.kind == "csv" else "variable"
        return InputError(f"{self.name}: no {kind} {column!r}; it has {self.names[:20]}")

    def values(self, column: str, index: int | None = None) -> np.ndarray:
        if column not in self.names:
            raise self._missing(column)
        if self.kind == "csv":
            if index is not None:
                raise InputError(f"{self.name}: index applies to MATLAB matrices, not to CSV column {column!r}")
            col = self._frame[column]
            num = pd.to_numeric(col, errors="coerce")
            bad = num.isna().to_numpy() & col.notna().to_numpy()
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise InputError(
                    f"{self.name}: column {column!r} line {i + 2} holds {col.iloc[i]!r}, not a number "
                    f"(a missing value is an empty cell or NaN)"
                )
            return num.to_numpy(dtype=np.float64)
        a = self._vars[column]
        if a.dtype.kind not in "fiub":
            raise InputError(f"{self.name}: variable {column!r} has type {a.dtype}, expected numbers")
        a = np.asarray(a, dtype=np.float64)
        if index is not None:
            if a.ndim != 2 or not 1 <= index <= a.shape[1]:
                raise InputError(f"{self.name}: variable {column!r} of shape {a.shape} has no column {index} (1-based)")
            return a[:, index - 1]
        if a.ndim > 2 or (a.ndim == 2 and min(a.shape) != 1):
            raise InputError(f"{self.name}: variable {column!r} has shape {a.shape}; give index = k to pick a column")
        return a.ravel()

    def times(self, column: str, fmt: str) -> np.ndarray:
        """Times of the rows: float seconds ("seconds") or int64 ns since 1970 UTC ("iso8601")."""
        if fmt == "seconds":
            t = self.values(column)
            missing = ~np.isfinite(t)
        else:
            if self.kind != "csv":
                raise InputError(f"{self.name}: ISO 8601 times are read from CSV only; store seconds in MAT files")
            if column not in self.names:
                raise self._missing(column)
            col = self._frame[column].astype("string").str.strip()
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    ts = pd.to_datetime(col, utc=True, format="ISO8601")
            except (ValueError, TypeError, OverflowError) as exc:
                raise InputError(f"{self.name}: time column {column!r} is not ISO 8601 ({' '.join(str(exc).split())})") from None
            missing = ts.isna().to_numpy()
            # Integer nanoseconds: float64 nanoseconds since 1970 would keep only about 0.25 us.
            t = ts.to_numpy(dtype="datetime64[ns]").astype(np.int64)
        bad = np.flatnonzero(missing)
        if bad.size:
            raise InputError(f"{self.name}: time {column!r} is missing at line {bad[0] + 2}; every row needs a time")
        return t


def _load_mat(path: Path) -> dict:
    if h5py.is_hdf5(path):  # MATLAB v7.3
        out = {}
        with h5py.File(path, "r") as f:
            for key, obj in f.items():
                if isinstance(obj, h5py.Dataset) and not key.startswith("#"):
                    # HDF5 stores MATLAB's column-major arrays transposed.
                    out[key] = np.asarray(obj[()]).T
        return out
    from scipy.io import loadmat

    data = loadmat(path, squeeze_me=False)
    return {k: np.asarray(v) for k, v in data.items() if not k.startswith("__")}


# ---------------------------------------------------------------------- import


def import_event(mapping_path, out_path=None):
    """Build an event from field files described by a mapping; optionally write it.

    Parameters
    ----------
    mapping_path : str or os.PathLike
        TOML mapping (see the module docstring).
    out_path : str or os.PathLike, optional
        Event file to write atomically (``vivbench.io.write_event``).

    Returns
    -------
    xarray.DataTree
        The event, ``source = "field"`` unless the mapping says otherwise,
        on the event grid (records at other rates resampled), with the unit
        conversions, the original rates, the sensor positions and each
        section's distance to its nearest anemometer (when the mapping gives
        positions) and the repairs in root attributes.

    Raises
    ------
    InputError
        One line naming the mapping or data file and the problem.
    """
    m = load_mapping(mapping_path)
    tables: dict[_Source, _Table] = {}

    def table(p: _Source) -> _Table:
        if p not in tables:
            tables[p] = _Table(p)
        return tables[p]

    fmts = {c.time_format for c in m["channels"]}
    start = m["start_time"]
    if start is None and "seconds" in fmts:
        raise InputError(f"{mapping_path}: start_time is required when times are in seconds (e.g. start_time = \"2026-01-01T00:00:00Z\")")
    start_ns = None
    if start is not None:
        try:
            start_ns = int(pd.Timestamp(start).tz_convert("UTC").value)
        except (ValueError, TypeError):
            raise InputError(f"{mapping_path}: start_time {start!r} is not an ISO 8601 UTC instant such as 2026-01-01T00:00:00Z") from None
    # Absolute ISO times of every source, read once, give the default start.
    raw_times = {}
    for c in m["channels"]:
        key = (c.file, c.time, c.time_format)
        if key not in raw_times:
            raw_times[key] = table(c.file).times(c.time, c.time_format)
    if start_ns is None:
        start_ns = int(min(t.min() for t in raw_times.values()))
        start = pd.Timestamp(start_ns, tz="UTC").isoformat().replace("+00:00", "Z")

    quality = {"quality_rows_reordered": 0, "quality_duplicates_dropped": 0}
    attrs: dict = {"import_mapping": Path(mapping_path).name}
    sources = {}
    for key, t in raw_times.items():
        file, _, fmt = key
        seconds = (t - np.int64(start_ns)) / 1e9 if fmt == "iso8601" else t
        order, keep, n_reordered, n_dups = _repair_time(seconds, str(file))
        quality["quality_rows_reordered"] += n_reordered
        quality["quality_duplicates_dropped"] += n_dups
        sources[key] = (seconds[order][keep], order[keep])

    data = {}
    for group in _GROUPS:
        chans = [c for c in m["channels"] if c.group == group]
        keys = list(dict.fromkeys((c.file, c.time, c.time_format) for c in chans))
        rates = {}
        for c in chans:
            k = (c.file, c.time, c.time_format)
            rates[k] = measured_rate(sources[k][0], str(c.file), group, c.rate)
        nominal = NOMINAL_RATES[group]
        on_grid = all(abs(r / nominal - 1.0) <= FIELD_RATE_TOLERANCE for r in rates.values())
        if on_grid:
            t_group, rows = _merge_times([sources[k][0] for k in keys], [str(k[0]) for k in keys], group)
        else:
            t_group = regular_grid(min(sources[k][0][0] for k in keys), max(sources[k][0][-1] for k in keys), nominal)
        attrs[f"import_rate_{group}_hz"] = float(min(rates.values()))
        attrs[f"import_resampled_{group}"] = int(not on_grid)
        group_data = {}
        for c in chans:
            k = (c.file, c.time, c.time_format)
            tab = table(c.file)
            raw = tab.values(c.column, c.index)
            if raw.shape[0] != raw_times[k].shape[0]:
                raise InputError(f"{tab.name}: {c.column!r} has {raw.shape[0]} values but the time {c.time!r} has {raw_times[k].shape[0]}")
            if on_grid:
                vals = np.full(t_group.size, np.nan)
                vals[rows[keys.index(k)]] = raw[sources[k][1]]
            else:
                vals = resample_to_grid(sources[k][0], raw[sources[k][1]], rates[k], t_group, tab.name)
            group_data[(c.var, c.section)] = (vals, c)
        data[group] = (t_group, group_data)

    sections = m["sections"]
    arrays = {}
    for group in _GROUPS:
        t, gd = data[group]
        arrays[f"{group}_time"] = t
        quality[f"quality_missing_{group}"] = int(sum(np.isnan(vals).sum() for vals, _ in gd.values()))
        for (var, sec), (_, c) in gd.items():
            if var != "direction":
                attrs[f"import_units_{var}_{sec}"] = c.units
                attrs[f"import_factor_{var}_{sec}"] = float(_UNITS[group][c.units])
    cols = []
    for sec in sections:
        a, ca = data["accel"][1][("acc", sec)]
        check_acc_magnitude(a, ca.units, where=f"{ca.file}: column {ca.column!r}", labels=[f"({sec})"])
        cols.append(a * ACC_UNITS[ca.units])
    arrays["acc"] = np.column_stack(cols)
    anem = [_anemometer_wind(data["wind"][1], info) for info in m["anemometers"]]
    if m["positions_m"] is None:  # one anemometer per section, in order
        weights = np.eye(len(sections))
    else:
        weights, distance = span_weights([i["position_m"] for i in m["anemometers"]], m["positions_m"], m["wind_rule"])
        attrs["import_span_length_m"] = m["span_length_m"]
        attrs["import_wind_rule"] = m["wind_rule"]
        for info in m["anemometers"]:
            attrs[f"import_anemometer_position_m_{info['name']}"] = info["position_m"]
        for sec, pos, d in zip(sections, m["positions_m"], distance):
            attrs[f"import_position_m_{sec}"] = pos
            attrs[f"wind_distance_m_{sec}"] = float(d)
    for k, var in enumerate(("u", "v", "w")):
        out = np.zeros((arrays["wind_time"].size, len(sections)))
        for j in range(len(sections)):
            for i in np.flatnonzero(weights[:, j]):
                out[:, j] += weights[i, j] * anem[i][k]
        arrays[var] = out
    attrs["import_sources"] = "; ".join(sorted({p.name for src in tables for p in src.paths}))
    attrs.update(quality)
    label = str(mapping_path)
    try:
        tree = build_event(
            event_id=m["event_id"], start_time=start, source=m["source"], span_azimuth_deg=m["span_azimuth_deg"],
            wind_time=arrays["wind_time"], u=arrays["u"], v=arrays["v"], w=arrays["w"],
            accel_time=arrays["accel_time"], acc=arrays["acc"], attrs=attrs, sections=sections,
        )
    except EventFormatError as exc:
        raise InputError(f"{label}: {exc.problem}") from None
    if out_path is not None:
        write_event(tree, out_path)
    return tree


def _anemometer_wind(gd: dict, info: dict):
    """East, north and up wind (m/s) of one anemometer, its magnitude checked in the declared unit."""
    name = info["name"]
    chans = {var: vc for (var, sec), vc in gd.items() if sec == name}
    speed_vars = [v for v in chans if v != "direction"]
    units = {chans[v][1].units for v in speed_vars}
    one_unit = len(units) == 1
    vals = {v: (x if one_unit or v == "direction" else x * WIND_UNITS[chans[v][1].units]) for v, (x, _) in chans.items()}
    east, north, up = to_east_north_up(info["format"], vals, info["heading_deg"])
    unit = units.pop() if one_unit else "m/s"
    first, second = (chans["u"][1], chans["v"][1]) if "u" in chans else (chans["speed"][1], chans["direction"][1])
    check_wind_magnitude(east, north, unit, where=f"{first.file}: columns {first.column!r}, {second.column!r}",
                         labels=[f"({name})"])
    factor = WIND_UNITS[unit]
    return east * factor, north * factor, up * factor


def _repair_time(t: np.ndarray, name: str):
    """Sort a few swapped rows and drop repeated time stamps.

    Returns the sorting order, the mask of kept rows (in sorted order), the
    number of rows moved and of rows dropped.
    """
    n = t.size
    if n < 2:
        raise InputError(f"{name}: {n} row(s); at least 2 needed")
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size > max(1, _MAX_REORDER_FRACTION * n):
        i = back[0] + 1
        raise InputError(
            f"{name}: time goes back {back.size} times, first at line {i + 2} (from {float(t[i - 1])!r} s to "
            f"{float(t[i])!r} s after start); sort the file or fix the clock (up to 1 % of rows out of order are sorted)"
        )
    order = np.argsort(t, kind="stable")
    n_reordered = int(np.sum(order != np.arange(n)))
    ts = t[order]
    keep = np.concatenate(([True], np.diff(ts) > 0))
    return order, keep, n_reordered, int(n - keep.sum())


def _merge_times(times: list[np.ndarray], names: list[str], group: str):
    """Union of the sources' times (matched to the microsecond) and each source's rows in it."""
    if len(times) == 1:
        return times[0], [np.arange(times[0].size)]
    keys = [np.round(t * 1e6).astype(np.int64) for t in times]
    all_keys, first = np.unique(np.concatenate(keys), return_index=True)
    t_union = np.concatenate(times)[first]
    step_union = float(np.median(np.diff(all_keys)))
    step_min = min(float(np.median(np.diff(k))) for k in keys)
    if step_union < 0.75 * step_min:
        raise InputError(
            f"{', '.join(names)}: the {group} files' time stamps do not line up (merged they step every "
            f"{step_union / 1e6:.4g} s instead of {step_min / 1e6:.4g} s); the files of one group must share one sample clock"
        )
    return t_union, [np.searchsorted(all_keys, k) for k in keys]
