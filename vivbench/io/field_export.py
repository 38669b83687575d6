"""Export of an event as field files (CSV or MATLAB) with the mapping that imports them back.

The inverse of :mod:`vivbench.io.fieldimport`, for worked examples and tests:
the files look like those a monitoring system writes, in the units asked for.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pandas as pd

from vivbench.core.errors import InputError
from vivbench.io.event import event_arrays
from vivbench.io.fieldimport import TIME_FORMATS
from vivbench.io.netcdf import atomic_path
from vivbench.io.quality import ACC_UNITS, WIND_UNITS

__all__ = ["export_csv", "export_mat"]


def _toml_value(v) -> str:
    if isinstance(v, str):
        return json.dumps(v)
    return repr(float(v)) if isinstance(v, float) else str(v)


def _write_text(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def _mapping_text(tree, *, groups: dict, event_id: str | None = None) -> str:
    lines = [
        f"event_id = {_toml_value(event_id or str(tree.attrs['event_id']))}",
        f"start_time = {_toml_value(str(tree.attrs['start_time']))}",
        f"span_azimuth_deg = {_toml_value(float(tree.attrs['span_azimuth_deg']))}",
        "",
    ]
    for group, (settings, sections) in groups.items():
        lines.append(f"[{group}]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in settings.items()]
        lines.append("")
        for sec, entries in sections.items():
            lines.append(f"[{group}.{sec}]")
            lines += [f"{k} = {v}" for k, v in entries.items()]
            lines.append("")
    return "\n".join(lines)


def _time_strings(t: np.ndarray, start_time: str) -> np.ndarray:
    start = pd.Timestamp(start_time).tz_convert("UTC").tz_localize(None)
    stamps = np.datetime64(start.to_datetime64(), "ns") + np.round(t * 1e9).astype("timedelta64[ns]")
    return np.char.add(np.datetime_as_string(stamps, unit="us"), "Z")


def export_csv(tree, out_dir, *, layout: str = "per_section", wind_units: str = "m/s", acc_units: str = "m/s^2",
               time_format: str = "seconds", event_id: str | None = None):
    """Write an event as CSV files plus a mapping that imports them back.

    Parameters
    ----------
    tree : xarray.DataTree
        A valid event (e.g. synthetic); its truth is not exported.
    out_dir : str or os.PathLike
        Directory for the files (created).
    layout : {"per_section", "single"}
        One file per sensor (``wind_S1.csv`` with time, u, v, w;
        ``accel_S1.csv`` with time, acc) or one file per group (``wind.csv``
        with time, u_S1, v_S1, w_S1, ...; ``accel.csv`` with time, acc_S1, ...).
    wind_units, acc_units : str
        Units written (keys of ``vivbench.io.quality.WIND_UNITS`` / ``ACC_UNITS``).
    time_format : {"seconds", "iso8601"}
        Times as seconds since start_time or as ISO 8601 UTC timestamps (microseconds).
    event_id : str, optional
        Event id written in the mapping (default: the event's own).

    Returns
    -------
    pathlib.Path
        The mapping file ``mapping.toml`` in ``out_dir``.
    """
    if layout not in ("per_section", "single"):
        raise InputError(f"layout must be 'per_section' or 'single'; got {layout!r}")
    if wind_units not in WIND_UNITS or acc_units not in ACC_UNITS:
        raise InputError(f"units must be one of {list(WIND_UNITS)} (wind) and {list(ACC_UNITS)} (acc); got {wind_units!r}, {acc_units!r}")
    if time_format not in TIME_FORMATS:
        raise InputError(f"time_format must be one of {TIME_FORMATS}; got {time_format!r}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    arr = event_arrays(tree)
    sections = list(arr["sections"])
    groups = {}
    for group, variables, units, factor in (
        ("wind", ("u", "v", "w"), wind_units, WIND_UNITS[wind_units]),
        ("accel", ("acc",), acc_units, ACC_UNITS[acc_units]),
    ):
        t = arr[f"{group}_time"]
        tcol = _time_strings(t, str(tree.attrs["start_time"])) if time_format == "iso8601" else t
        settings = {"time": "time", "time_format": time_format, "units": units}
        sec_entries = {}
        if layout == "single":
            fname = f"{group}.csv"
            settings = {"file": fname, **settings}
            frame = {"time": tcol}
            for sec_i, sec in enumerate(sections):
                for var in variables:
                    frame[f"{var}_{sec}"] = np.asarray(arr[var][:, sec_i], dtype=np.float64) / factor
                sec_entries[sec] = {var: json.dumps(f"{var}_{sec}") for var in variables}
            _write_csv(out / fname, frame)
        else:
            for sec_i, sec in enumerate(sections):
                fname = f"{group}_{sec}.csv"
                frame = {"time": tcol}
                for var in variables:
                    frame[var] = np.asarray(arr[var][:, sec_i], dtype=np.float64) / factor
                _write_csv(out / fname, frame)
                sec_entries[sec] = {"file": json.dumps(fname), **{var: json.dumps(var) for var in variables}}
        groups[group] = (settings, sec_entries)
    mapping = out / "mapping.toml"
    _write_text(mapping, _mapping_text(tree, groups=groups, event_id=event_id))
    return mapping


def _write_csv(path: Path, frame: dict) -> None:
    with atomic_path(path) as tmp:
        # float_format=None writes the shortest repr: the float64 values read back exactly.
        pd.DataFrame(frame).to_csv(tmp, index=False, na_rep="NaN")


def export_mat(tree, out_dir, *, version: str = "5", acc_units: str = "m/s^2"):
    """Write an event as one MATLAB file ``event.mat`` plus a mapping that imports it.

    Variables: ``wind_time`` (n_w, 1) s; ``u``, ``v``, ``w`` (n_w, n_sec) m/s;
    ``accel_time`` (n_a, 1) s; ``acc`` (n_a, n_sec) in ``acc_units``.

    Parameters
    ----------
    version : {"5", "7.3"}
        MAT v5 (scipy.io.savemat) or v7.3 (HDF5 with MATLAB's 512-byte header,
        arrays stored transposed as MATLAB does).

    Returns
    -------
    pathlib.Path
        The mapping file ``mapping.toml`` in ``out_dir``.
    """
    if version not in ("5", "7.3"):
        raise InputError(f"version must be '5' or '7.3'; got {version!r}")
    if acc_units not in ACC_UNITS:
        raise InputError(f"acc_units must be one of {list(ACC_UNITS)}; got {acc_units!r}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    arr = event_arrays(tree)
    sections = list(arr["sections"])
    variables = {
        "wind_time": arr["wind_time"][:, None],
        "u": np.asarray(arr["u"], dtype=np.float64),
        "v": np.asarray(arr["v"], dtype=np.float64),
        "w": np.asarray(arr["w"], dtype=np.float64),
        "accel_time": arr["accel_time"][:, None],
        "acc": np.asarray(arr["acc"], dtype=np.float64) / ACC_UNITS[acc_units],
    }
    target = out / "event.mat"
    with atomic_path(target, suffix=".mat") as tmp:
        if version == "5":
            from scipy.io import savemat

            savemat(tmp, variables, format="5")
        else:
            with h5py.File(tmp, "w", userblock_size=512) as f:
                for k, v in variables.items():
                    ds = f.create_dataset(k, data=np.ascontiguousarray(v.T))
                    ds.attrs["MATLAB_class"] = np.bytes_("double")
            header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created by: vivbench. HDF5 schema 1.00 ."
            with open(tmp, "r+b") as fh:
                fh.write(header.ljust(116) + b"\x00" * 8 + b"\x00\x02IM")
    groups = {
        "wind": ({"file": "event.mat", "time": "wind_time", "units": "m/s"},
                 {sec: {var: f"{{ column = \"{var}\", index = {i + 1} }}" for var in ("u", "v", "w")}
                  for i, sec in enumerate(sections)}),
        "accel": ({"file": "event.mat", "time": "accel_time", "units": acc_units},
                  {sec: {"acc": f"{{ column = \"acc\", index = {i + 1} }}"} for i, sec in enumerate(sections)}),
    }
    mapping = out / "mapping.toml"
    _write_text(mapping, _mapping_text(tree, groups=groups))
    return mapping
