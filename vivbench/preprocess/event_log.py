"""Events from a continuous log: import the field files, detect the VIV events, write one event file each and a catalogue.

The log is read by the field import (:func:`vivbench.io.import_event`: the
same TOML mapping, files, globs, units, time zones, rates and sensor
positions), the events found by :func:`~vivbench.preprocess.detect_events`,
and each event, with its margins, is written in the event format that
``vivbench identify`` reads.
"""

from __future__ import annotations

import csv
import io as _io
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

from vivbench.core.errors import InputError
from vivbench.io.event import build_event, event_arrays, write_event
from vivbench.io.fieldimport import import_event
from vivbench.io.netcdf import atomic_path
from vivbench.preprocess.event_detection import EventDetection, EventDetectionConfig, detect_events
from vivbench.preprocess.vibration import modal_frequency

__all__ = ["EventCatalogue", "CATALOGUE_COLUMNS", "cut_events", "find_events"]

#: Columns of ``catalogue.csv``.
CATALOGUE_COLUMNS = ("event_id", "file", "start", "end", "duration_s", "file_start", "file_end", "frequency_hz",
                     "peak_amplitude_m", "peak_section", "peak_acceleration_m_s2", "mean_wind_m_s",
                     "wind_direction_deg", "missing_fraction")
_OWN_ATTRS = ("format", "format_version", "event_id", "start_time", "source", "span_azimuth_deg")


@dataclass(frozen=True)
class EventCatalogue:
    """What :func:`find_events` wrote.

    Attributes
    ----------
    files : list of pathlib.Path
        The event files, in time order.
    catalogue : pathlib.Path
        ``catalogue.csv``.
    rows : list of dict
        The catalogue's rows (:data:`CATALOGUE_COLUMNS`, as text).
    detection : EventDetection
        The detector's result on the whole log.
    """

    files: list
    catalogue: Path
    rows: list
    detection: EventDetection


def _iso(origin: pd.Timestamp, seconds: float) -> str:
    stamp = origin + pd.Timedelta(microseconds=round(float(seconds) * 1e6))
    return stamp.strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def _event_frequency(t: np.ndarray, acc: np.ndarray, f_mode: float, segment_s: float) -> float:
    """The event's own spectral peak near the mode, Hz (NaN when its spectrum has none)."""
    try:
        return modal_frequency(t, acc, (0.5 * f_mode, 1.5 * f_mode), segment_s=min(segment_s, float(t[-1] - t[0])))
    except InputError:
        return float("nan")


def cut_events(tree: xr.DataTree, detection: EventDetection, config: EventDetectionConfig, *,
               prefix: str = "EV", mapping: str = "") -> list:
    """Cut the detected events, with their margins, out of a log held as one event.

    Parameters
    ----------
    tree : xarray.DataTree
        The log in the event format (e.g. from :func:`vivbench.io.import_event`).
    detection : EventDetection
        The detector's result on the log's acceleration.
    config : EventDetectionConfig
        Its ``margin_s`` and ``segment_s`` are used.
    prefix : str
        Event ids are ``<prefix>_001``, ``<prefix>_002``, ...
    mapping : str
        Name of the mapping file, recorded in each event.

    Returns
    -------
    list of (xarray.DataTree, dict)
        Each event and its catalogue row (without ``file``).
    """
    arr = event_arrays(tree, truth=False)
    origin = pd.Timestamp(str(tree.attrs["start_time"])).tz_convert("UTC").tz_localize(None)
    ta, tw = arr["accel_time"], arr["wind_time"]
    lo_log, hi_log = max(ta[0], tw[0]), min(ta[-1], tw[-1])
    sections = list(arr["sections"])
    keep = {k: v for k, v in tree.attrs.items() if k not in _OWN_ATTRS and not k.startswith("quality_missing_")}
    width = max(3, len(str(len(detection.intervals))))
    out = []
    for n, (start, end) in enumerate(detection.intervals, start=1):
        eid = f"{prefix}_{n:0{width}d}"
        lo, hi = max(start - config.margin_s, lo_log), min(end + config.margin_s, hi_log)
        ia = np.flatnonzero((ta >= lo) & (ta <= hi))
        t0 = float(ta[ia[0]])
        iw = np.flatnonzero((tw >= t0) & (tw <= hi))
        acc, u, v, w = arr["acc"][ia], arr["u"][iw], arr["v"][iw], arr["w"][iw]
        core_a = (ta[ia] >= start) & (ta[ia] <= end)
        core_w = (tw[iw] >= start) & (tw[iw] <= end)
        peak, k = detection.peak(start, end)
        f_event = _event_frequency(ta[ia][core_a], acc[core_a], detection.frequency_hz, config.segment_s)
        mu, mv = np.nanmean(u[core_w]), np.nanmean(v[core_w])
        speed = float(np.nanmean(np.hypot(u[core_w], v[core_w])))
        direction = float(np.degrees(np.arctan2(-mu, -mv)) % 360.0)  # where the wind comes from
        attrs = {**keep,
                 "detection_mapping": mapping,
                 "detection_log_start_time": str(tree.attrs["start_time"]),
                 "detection_start_s": float(start - t0), "detection_end_s": float(end - t0),
                 "detection_frequency_hz": detection.frequency_hz,
                 "detection_peak_amplitude_m": peak,
                 "quality_missing_wind": int(np.isnan(u).sum() + np.isnan(v).sum() + np.isnan(w).sum()),
                 "quality_missing_accel": int(np.isnan(acc).sum())}
        for j, sec in enumerate(sections):
            attrs[f"detection_noise_floor_m_{sec}"] = float(detection.noise_floor_m[j])
            attrs[f"detection_threshold_m_{sec}"] = float(detection.threshold_m[j])
        event = build_event(event_id=eid, start_time=_iso(origin, t0), source=str(tree.attrs["source"]),
                            span_azimuth_deg=float(tree.attrs["span_azimuth_deg"]),
                            wind_time=tw[iw] - t0, u=u, v=v, w=w, accel_time=ta[ia] - t0, acc=acc,
                            attrs=attrs, sections=sections)
        omega2 = (2.0 * np.pi * detection.frequency_hz) ** 2
        row = {"event_id": eid, "start": _iso(origin, start), "end": _iso(origin, end),
               "duration_s": f"{end - start:.1f}", "file_start": _iso(origin, t0), "file_end": _iso(origin, ta[ia[-1]]),
               "frequency_hz": f"{f_event:.4f}" if np.isfinite(f_event) else "", "peak_amplitude_m": f"{peak:.5f}", "peak_section": sections[k],
               "peak_acceleration_m_s2": f"{peak * omega2:.5f}", "mean_wind_m_s": f"{speed:.2f}",
               "wind_direction_deg": f"{direction:.1f}",
               "missing_fraction": f"{float(np.isnan(acc[core_a]).any(axis=1).mean()):.4f}"}
        out.append((event, row))
    return out


def find_events(mapping_path, out_dir, config: EventDetectionConfig | None = None, *,
                progress: Callable[[str], None] | None = None) -> EventCatalogue:
    """Find the VIV events of a continuous log and write one event file each plus ``catalogue.csv``.

    Parameters
    ----------
    mapping_path : str or os.PathLike
        The TOML mapping of the log's field files (docs/field_import.md); its
        ``event_id`` is the prefix of the events' ids.
    out_dir : str or os.PathLike
        Directory for ``<event_id>.nc`` and ``catalogue.csv`` (created).
    config : EventDetectionConfig, optional
    progress : callable, optional
        Called with a short description after each step.

    Returns
    -------
    EventCatalogue

    Raises
    ------
    InputError
        Anything the import refuses, a record the detector cannot use, or a
        log without any event: one line naming the mapping. Nothing is
        written then; every file is written atomically and the catalogue last.
    """
    config = config or EventDetectionConfig()
    mapping_path = Path(mapping_path)
    tree = import_event(mapping_path)
    if progress is not None:
        progress("imported")
    arr = event_arrays(tree, truth=False)
    detection = detect_events(arr["accel_time"], arr["acc"], config, name=str(mapping_path))
    if progress is not None:
        progress("detected")
    if not len(detection.intervals):
        t = arr["accel_time"]
        rule = (f"{config.threshold_m:g} m" if config.threshold_m is not None else
                f"{config.threshold_factor:g} x the noise floor, {np.max(detection.threshold_m):.3g} m")
        raise InputError(
            f"{mapping_path}: no VIV event in {t[-1] - t[0]:.0f} s of records: the amplitude at the "
            f"{detection.frequency_hz:.4g} Hz mode never stayed above its threshold ({rule}) for "
            f"{config.min_duration_s:g} s (highest {np.nanmax(detection.amplitude):.3g} m); nothing written")
    events = cut_events(tree, detection, config, prefix=str(tree.attrs["event_id"]), mapping=mapping_path.name)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files, rows = [], []
    for event, row in events:
        path = write_event(event, out / f"{row['event_id']}.nc")
        files.append(path)
        rows.append({"event_id": row["event_id"], "file": path.name, **{k: row[k] for k in CATALOGUE_COLUMNS[2:]}})
        if progress is not None:
            progress(row["event_id"])
    buf = _io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(CATALOGUE_COLUMNS), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    catalogue = out / "catalogue.csv"
    with atomic_path(catalogue) as tmp:
        tmp.write_text(buf.getvalue())
    return EventCatalogue(files=files, catalogue=catalogue, rows=rows, detection=detection)
