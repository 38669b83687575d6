"""Event files (docs/formats.md): write, read and summarise one event; list a campaign's events.

The layout, its constants and the check of an event in memory are in
:mod:`vivbench.io.event_schema`, the assembly of an event from arrays in
:mod:`vivbench.io.event_build`; both are importable from here too.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import xarray as xr

from vivbench.io.event_build import build_event
from vivbench.io.event_schema import (CHANGE_VARIABLES, COEF_UNITS, EVENT_ID_PATTERN, FORMAT, FORMAT_VERSION,
                                      NOMINAL_RATES, EventFormatError, validate_event, validate_root_attributes)
from vivbench.io.netcdf import NETCDF_ENGINE, write_netcdf_atomic

__all__ = ["EventFormatError", "FORMAT", "FORMAT_VERSION", "NOMINAL_RATES", "COEF_UNITS", "build_event", "validate_event", "write_event", "read_event", "event_arrays", "list_events",
           "EventSummary", "read_event_summary", "peek_event_id"]


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
        _check_stored_shapes(path, name, skip=() if truth else ("/truth",))
        if truth:
            tree = xr.load_datatree(path, engine=NETCDF_ENGINE, decode_times=False, decode_timedelta=False)
        else:
            with xr.open_datatree(path, engine=NETCDF_ENGINE, decode_times=False, decode_timedelta=False) as lazy:
                tree = xr.DataTree.from_dict(
                    {node.path: node.to_dataset(inherit=False) for node in lazy.subtree
                     if node.path != "/truth" and not node.path.startswith("/truth/")}).load()
    except EventFormatError:
        raise
    except Exception as exc:  # noqa: BLE001 - any reader failure means "not an event file"
        raise EventFormatError(name, f"cannot be read as NetCDF-4/HDF5 ({type(exc).__name__}: {exc})") from exc
    for node in tree.subtree:
        for var in node.variables.values():
            var.encoding = {}
    validate_event(tree, name=name)
    return tree


def _check_stored_shapes(path: Path, name: str, skip: tuple = ()) -> None:
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
                    raise EventFormatError(name,
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
            validate_root_attributes(attrs, name)
            truth = tree["truth"].to_dataset().load() if "truth" in tree.children else None
            if "accel" not in tree.children:
                raise EventFormatError(name, "missing group /accel")
            accel_time = np.asarray(tree["accel"]["time"].values)
    except EventFormatError:
        raise
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
        (n_t, 4), dimensionless, when stored, ``truth_yaw`` (n_t, n_sec) degrees when stored,
        and the coefficient curves
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
        for name in CHANGE_VARIABLES:
            if name in group.data_vars:
                out[name] = group[name].values
        if "yaw" in group.data_vars:
            out["truth_yaw"] = group["yaw"].values
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
        p for p in directory.glob("*.nc") if p.is_file() and EVENT_ID_PATTERN.fullmatch(p.name[: -len(".nc")])
    )
