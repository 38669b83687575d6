"""The window-result file format ``<event_id>.identify.nc``: schema, writer and typed reader.

This module owns the format. :func:`build_result` assembles the dataset that
:func:`vivbench.analysis.identify.identify_event` returns, :func:`write_result`
writes it atomically and :func:`read_result` is the one reader every later
stage uses (pooling, clustering, validation, forecasting, refits, the report).

One NetCDF-4 file per identified event, a flat dataset (no groups)::

    attributes   format = "vivbench-identify", format_version = 1, event_id,
                 source_file, event_source, f_mode_hz, f_mode_source, edge_s,
                 noise_std_m, span_azimuth_deg, coverage, identify_config_json,
                 vivbench_version, quality_* (see ATTRIBUTES)
    coordinates  window (window); equation (equation) "S1".."Sn";
                 feature (feature) 23 per section; order (order) 0..3;
                 time (time) s; section (section) "S1".."Sn"
    per window and equation
                 coef (window, equation, feature); threshold, aicc, rss,
                 n_terms, regime, identifiable, regimes_seen, n_equivalent,
                 amplitude_snr (window, equation); order_rms (window,
                 equation, order); inclusion (window, equation, feature),
                 ensemble optimiser only
    per window   cond, n_samples, window_start, window_end, window_segment
    per sample   A, U, dA (time, section); segment (time); yaw (time,
                 section), optional (files written before it existed lack it)

:data:`VARIABLES` and :data:`COORDINATES` give dims, dtype, units and meaning
of each; ``docs/formats.md`` is generated from them (:func:`markdown_table`).
"""

from __future__ import annotations

import numbers
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.io.netcdf import NETCDF_ENGINE, write_netcdf_atomic

__all__ = [
    "FORMAT", "FORMAT_VERSION", "FEATURES_PER_SECTION", "VariableSpec", "VARIABLES", "COORDINATES", "ATTRIBUTES",
    "WINDOW_FIT_VARIABLES", "ResultFormatError", "build_result", "write_result", "read_result", "list_results",
    "select_results", "result_path", "result_record", "result_noise_std", "result_wind_distance", "markdown_table", "markdown_attributes",
]

FORMAT = "vivbench-identify"
FORMAT_VERSION = 1
#: Library terms per section: column block k of ``coef`` holds the 23 terms of section k.
FEATURES_PER_SECTION = 23
_N_ORDERS = 4
_SUFFIX = ".identify.nc"


@dataclass(frozen=True)
class VariableSpec:
    """One variable (or coordinate) of the result file.

    Attributes
    ----------
    dims : tuple of str
        Dimension names, in order.
    dtype : str
        Stored dtype: "float64", "int8", "int32", "int64" or "str".
    units : str or None
        The ``units`` attribute written (None: none written).
    long_name : str
        The ``long_name`` attribute written; ``{method}`` is replaced by the
        differentiation method (``dA`` only).
    required : bool
        Every version-1 file has it (False: ``inclusion``, ensemble optimiser only).
    """

    dims: tuple[str, ...]
    dtype: str
    units: str | None
    long_name: str
    required: bool = True

    @property
    def kind(self) -> str:
        """numpy dtype kinds the reader accepts: "f" floats, "iu" integers, "U" strings."""
        return {"float64": "f", "str": "UO"}.get(self.dtype, "iu")


_WE = ("window", "equation")
#: Data variables in the order they are written (the order is part of the byte-identical output).
VARIABLES: dict[str, VariableSpec] = {
    "coef": VariableSpec(("window", "equation", "feature"), "float64", "1/s * m^(1-i) (m/s)^(-j)",
                         "selected model on the physical library A_l^i U_l^j"),
    "threshold": VariableSpec(_WE, "float64", "1", "STLSQ threshold of the selected model (standardised coefficients)"),
    "aicc": VariableSpec(_WE, "float64", "1", "AICc of the selected model"),
    "rss": VariableSpec(_WE, "float64", "m^2/s^2", "residual sum of squares"),
    "n_terms": VariableSpec(_WE, "int64", "1", "number of terms in the regression basis"),
    "regime": VariableSpec(_WE, "int8", "1", "regime of the selected model by the regime rule; 0: no model"),
    "identifiable": VariableSpec(_WE, "int8", "1", "every equally good competing model has the same regime, and the "
                                 "amplitude is above the noise floor (min_snr)"),
    "regimes_seen": VariableSpec(_WE, "int8", "1", "bit mask of regimes among equally good models (bit k-1: regime k)"),
    "n_equivalent": VariableSpec(_WE, "int64", "1", "equally good competing models found"),
    "order_rms": VariableSpec(("window", "equation", "order"), "float64", "m/s",
                              "RMS over the window of each order's contribution to dA/dt"),
    "cond": VariableSpec(("window",), "float64", "1", "condition number of the window's regression library"),
    "n_samples": VariableSpec(("window",), "int64", "1", "valid samples in the window"),
    "inclusion": VariableSpec(("window", "equation", "feature"), "float64", "1",
                              "inclusion probability of each regression-basis term over the bootstrap models "
                              "(ensemble optimiser)", required=False),
    "amplitude_snr": VariableSpec(_WE, "float64", "1", "mean amplitude over the window divided by the accelerometer "
                                  "noise floor in the vibration band (NaN: floor unknown)"),
    "window_start": VariableSpec(("window",), "float64", "s", "window start since event start"),
    "window_end": VariableSpec(("window",), "float64", "s", "window end since event start"),
    "window_segment": VariableSpec(("window",), "int32", "1", "preprocessing segment of the window"),
    "A": VariableSpec(("time", "section"), "float64", "m", "vibration amplitude (Hilbert envelope)"),
    "U": VariableSpec(("time", "section"), "float64", "m/s", "mean wind speed perpendicular to the span"),
    "dA": VariableSpec(("time", "section"), "float64", "m/s", "dA/dt ({method})"),
    "segment": VariableSpec(("time",), "int32", "1", "contiguous segment (-1: excluded)"),
    "yaw": VariableSpec(("time", "section"), "float64", "degree",
                        "yaw of the low-passed mean wind: signed angle to the span's normal from the anemometers' u, v "
                        "(NaN in wind gaps); absent from files written before it existed", required=False),
}

#: Variables with one value per (window, equation) model as fitted by the window estimator, in write order.
WINDOW_FIT_VARIABLES = ("coef", "threshold", "aicc", "rss", "n_terms", "regime", "identifiable", "regimes_seen",
                        "n_equivalent", "order_rms", "cond", "n_samples")

#: Coordinates in the order they are written; only ``time`` carries attributes.
COORDINATES: dict[str, VariableSpec] = {
    "window": VariableSpec(("window",), "int64", None, "window index 0..n_window-1, in time order"),
    "equation": VariableSpec(("equation",), "str", None, "section whose dA/dt the equation gives, 'S1'..'Sn'"),
    "feature": VariableSpec(("feature",), "str", None,
                            "library term, pysindy-style name such as 'A1^2 U1'; 23 per section: A_k^i U_k^j, i = 0..3, "
                            "j = 0..5, (i, j) != (0, 0); section k's block is columns 23(k-1)..23k-1"),
    "order": VariableSpec(("order",), "int64", None, "power i of A of an order contribution, 0..3"),
    "time": VariableSpec(("time",), "float64", "s", "time since event start"),
    "section": VariableSpec(("section",), "str", None, "deck section of A, U and dA, 'S1'..'Sn'"),
}

#: Root attributes: name -> (type, units, meaning). ``quality_*`` names are listed in the docs.
ATTRIBUTES: dict[str, tuple[str, str, str]] = {
    "format": ("str", "", f'"{FORMAT}"'),
    "format_version": ("int", "", f"{FORMAT_VERSION}; readers refuse newer versions"),
    "event_id": ("str", "", "the event's id (also the file stem)"),
    "source_file": ("str", "", "name of the event file identified"),
    "event_source": ("str", "", '"synthetic" or "field", from the event'),
    "f_mode_hz": ("float", "Hz", "frequency of the vibration mode used for the envelope"),
    "f_mode_source": ("str", "", '"given" (from the configuration) or "spectrum" (found)'),
    "edge_s": ("float", "s", "edge dropped at each end of every valid run (filter settling)"),
    "noise_std_m": ("float[n_section]", "m", "accelerometer noise in the band as displacement: the noise floor of A (NaN: unknown)"),
    "span_azimuth_deg": ("float", "deg", "direction of the span axis, degrees clockwise from north"),
    "wind_distance_m": ("float[n_section]", "m", "optional: each section's distance to the anemometer its wind was taken from (the event's wind_distance_m_<section>); absent when the event records none (one anemometer per section)"),
    "coverage": ("float", "1", "share of window-equations with a model that are flagged identifiable (NaN: none)"),
    "identify_config_json": ("str", "", "the IdentifyConfig as JSON (sorted keys)"),
    "vivbench_version": ("str", "", "version of vivbench that wrote the file"),
}

_FIXED_DIMS = {"order": _N_ORDERS}


class ResultFormatError(InputError):
    """A result file that is missing, unreadable or breaks the format; one-line message naming the file.

    Parameters
    ----------
    filename : str
        The file; the message starts with it.
    problem : str
        What is wrong; newlines are folded so that the message is one line.
    """

    def __init__(self, filename, problem: str):
        self.filename = str(filename)
        self.problem = " ".join(str(problem).split())
        super().__init__(f"{self.filename}: {self.problem}")

    def __reduce__(self):
        # Rebuild from both parts so the error survives pickling (worker processes).
        return (type(self), (self.filename, self.problem))


# ------------------------------------------------------------------------- build / write


def build_result(*, fit: Mapping[str, np.ndarray], window_start, window_end, window_segment, amplitude_snr,
                 time, A, U, dA, segment, sections: Sequence[str], features: Sequence[str],
                 derivative_method: str, attrs: Mapping, inclusion=None, yaw=None) -> xr.Dataset:
    """Assemble a result dataset in the layout of this format.

    Parameters
    ----------
    fit : mapping
        The window fit, one array per name of :data:`WINDOW_FIT_VARIABLES`:
        ``coef`` (n_window, n_section, 23 n_section), ``order_rms``
        (n_window, n_section, 4), ``cond`` and ``n_samples`` (n_window,),
        the others (n_window, n_section); units as in :data:`VARIABLES`.
        ``regime``, ``regimes_seen`` and ``identifiable`` (bool allowed) are
        stored as int8; the others keep their dtype.
    window_start, window_end : array_like, shape (n_window,), s
        Window bounds since the event start.
    window_segment : array_like, shape (n_window,)
        Preprocessing segment of each window (stored as int32).
    amplitude_snr : array_like, shape (n_window, n_section)
        Mean amplitude over the noise floor (dimensionless).
    time : array_like, shape (n_time,), s
        Preprocessing grid.
    A : array_like, shape (n_time, n_section), m
    U : array_like, shape (n_time, n_section), m/s
    dA : array_like, shape (n_time, n_section), m/s
    segment : array_like, shape (n_time,)
        Segment of each sample, -1 outside every segment (stored as int32).
    sections : sequence of str
        Section labels "S1".."Sn" (the ``equation`` and ``section`` coordinates).
    features : sequence of str
        The 23 n_section library term names (empty when there is no window).
    derivative_method : str
        Name of the differentiation method, recorded in ``dA``'s long_name.
    attrs : mapping
        Root attributes after ``format`` and ``format_version`` (see
        :data:`ATTRIBUTES`), in the order they are to be written.
    inclusion : array_like, shape (n_window, n_section, 23 n_section), optional
        Ensemble inclusion probabilities.
    yaw : array_like, shape (n_time, n_section), degrees, optional
        Yaw of the low-passed mean wind on the preprocessing grid.

    Returns
    -------
    xarray.Dataset
        Ready for :func:`write_result`.
    """
    values = dict(fit)
    for name in ("regime", "regimes_seen", "identifiable"):
        values[name] = np.asarray(values[name]).astype(np.int8)  # NetCDF has no boolean type
    if inclusion is not None:
        values["inclusion"] = inclusion
    if yaw is not None:
        values["yaw"] = np.asarray(yaw, dtype=float)
    values.update(amplitude_snr=amplitude_snr, window_start=window_start, window_end=window_end,
                  window_segment=np.asarray(window_segment).astype(np.int32), A=A, U=U, dA=dA,
                  segment=np.asarray(segment).astype(np.int32))
    data = {}
    for name, spec in VARIABLES.items():
        if name not in values:
            continue
        long_name = spec.long_name.format(method=derivative_method) if name == "dA" else spec.long_name
        data[name] = (spec.dims, values[name], {"units": spec.units, "long_name": long_name})
    n_w = np.shape(values["cond"])[0]
    sections = list(sections)
    coords = {
        "window": np.arange(n_w),
        "equation": sections,
        "feature": features if n_w else [],
        "order": np.arange(_N_ORDERS),
        "time": ("time", time, {"units": COORDINATES["time"].units, "long_name": COORDINATES["time"].long_name}),
        "section": sections,
    }
    own = {"format": FORMAT, "format_version": FORMAT_VERSION}
    clash = sorted(set(own) & set(attrs))
    if clash:
        raise ValueError(f"attrs must not set {', '.join(clash)} (the format's own attributes)")
    return xr.Dataset(data, coords=coords, attrs={**own, **attrs})


def result_path(out_dir: str | Path, event_id: str) -> Path:
    """Where the result of event ``event_id`` is written in ``out_dir``: ``out_dir/<event_id>.identify.nc``."""
    return Path(out_dir) / f"{event_id}{_SUFFIX}"


def write_result(ds: xr.Dataset, out_dir: str | Path) -> Path:
    """Write a result atomically as ``out_dir/<event_id>.identify.nc``.

    Parameters
    ----------
    ds : xarray.Dataset
        A result (see :func:`build_result`); its ``event_id`` attribute names the file.
    out_dir : str or os.PathLike
        Directory, created when missing.

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    ValueError
        ``ds`` is not a result of this format (nothing is written).
    """
    if ds.attrs.get("format") != FORMAT:
        raise ValueError(f"not an identification result (format attribute is {ds.attrs.get('format')!r}); "
                         f"nothing written to {out_dir}")
    return write_netcdf_atomic(ds, result_path(out_dir, ds.attrs["event_id"]))


# --------------------------------------------------------------------------------- read


def list_results(results_dir) -> list[Path]:
    """The ``<event_id>.identify.nc`` files of a directory, sorted by name.

    Raises
    ------
    ValueError
        The directory does not exist or holds no result file (the message names it).
    """
    d = Path(results_dir)
    if not d.is_dir():
        raise InputError(f"{d}: not a directory of identification results")
    files = sorted(d.glob(f"*{_SUFFIX}"))
    if not files:
        raise InputError(f"{d}: no identification results (<event_id>.identify.nc) in this directory")
    return files


def select_results(files: Sequence[Path], spec: str) -> list[Path]:
    """The result files of the events that ``spec`` names, in the order of ``files``.

    Parameters
    ----------
    files : sequence of Path
        ``<event_id>.identify.nc`` files in the campaign's order (:func:`list_results`: by name, the
        order in which :func:`vivbench.analysis.pool_results` and the change scan take the events).
    spec : str
        Comma-separated event ids and ranges over that order: ``E003``, ``E007..`` (from E007 on),
        ``..E006`` (up to E006), ``E002..E005`` (both ends included).

    Raises
    ------
    InputError
        An id that no file carries, a range whose first event comes after its last, or an empty
        selection (the message names the id and the first file's directory).
    """
    files = [Path(f) for f in files]
    if not files:
        raise InputError(f"no identification results to choose the events {spec!r} from")
    ids = [f.name.removesuffix(_SUFFIX) for f in files]
    where = files[0].parent
    index = {e: i for i, e in enumerate(ids)}

    def position(event_id: str, default: int) -> int:
        if not event_id:
            return default
        if event_id not in index:
            raise InputError(f"{where}: no identification result of event {event_id!r} (--events {spec!r}); "
                             f"the events are {ids[0]}..{ids[-1]}")
        return index[event_id]

    keep = np.zeros(len(files), dtype=bool)
    items = [x.strip() for x in str(spec).split(",")]
    if not any(items):
        raise InputError(f"--events must name at least one event id or range (E003, E007.., ..E006, E002..E005); "
                         f"got {spec!r}")
    for item in items:
        if not item:
            continue
        if ".." in item:
            first, _, last = (x.strip() for x in item.partition(".."))
            a, b = position(first, 0), position(last, len(files) - 1)
            if a > b:
                raise InputError(f"{where}: the range {item!r} of --events starts after it ends ({ids[a]} comes after "
                                 f"{ids[b]} in the campaign's order)")
            keep[a:b + 1] = True
        else:
            keep[position(item, 0)] = True
    return [f for f, k in zip(files, keep) if k]


def read_result(path, variables: Iterable[str] | None = None, *, optional: Iterable[str] = ()) -> xr.Dataset:
    """Load an identification result into memory, close the file and check it against the format.

    Parameters
    ----------
    path : str or os.PathLike
        An ``<event_id>.identify.nc``.
    variables : iterable of str, optional
        Data variables to load and check (every coordinate is always loaded);
        None: every variable of the file, of which all required ones
        (:data:`VARIABLES`) must be present.
    optional : iterable of str
        Further variables loaded when the file has them (with ``variables``).

    Returns
    -------
    xarray.Dataset
        In memory (no file handle stays open), attributes included.

    Raises
    ------
    ResultFormatError
        A ``ValueError`` with a one-line message starting with the file name:
        missing file, not NetCDF-4, another format, a newer (or unknown)
        ``format_version``, a missing variable or coordinate, wrong dimensions,
        dtype or shape.
    """
    path = Path(path)
    if not path.is_file():
        raise ResultFormatError(path, "no such result file")
    try:
        with xr.open_dataset(path, engine=NETCDF_ENGINE) as ds:
            _check_header(ds.attrs)
            if variables is None:
                wanted = [n for n, s in VARIABLES.items() if s.required]
                keep = list(ds.data_vars)
            else:
                wanted = list(dict.fromkeys(variables))
                keep = wanted + [n for n in optional if n in ds.data_vars and n not in wanted]
            missing = [n for n in wanted if n not in ds.data_vars]
            if missing:
                raise _Breach(f"result lacks the variable{'s' if len(missing) > 1 else ''} {', '.join(missing)}")
            ds = ds.drop_vars([n for n in ds.data_vars if n not in keep]).load()
    except _Breach as breach:
        raise ResultFormatError(path, str(breach)) from None
    except Exception as exc:  # noqa: BLE001 - any reader failure means "not a result file"
        raise ResultFormatError(path, f"cannot be read as a NetCDF-4 result ({type(exc).__name__}: {exc})") from exc
    try:
        _check_layout(ds)
    except _Breach as breach:
        raise ResultFormatError(path, str(breach)) from None
    return ds


def result_record(ds: xr.Dataset) -> Record:
    """The record of an identification result, for any model of the protocol (docs/methods.md).

    Parameters
    ----------
    ds : xarray.Dataset
        A result read by :func:`read_result` with at least ``time`` (s), ``A``
        (m), ``U`` (m/s) and ``dA`` (m/s), each (time, section) but ``time``,
        and the attribute ``event_id``.

    Returns
    -------
    Record
        ``event_id`` from the attribute; ``t``, ``A``, ``U``, ``dA`` and (when
        the result has it) ``yaw`` copied from the result (dA is NaN outside
        the identification's segments).

    Raises
    ------
    InputError
        One line naming the result's file (or "result" when it has none) when
        a variable or the event id is missing.
    """
    source = ds.encoding.get("source", "result")
    missing = [n for n in ("A", "U", "dA") if n not in ds.data_vars] + (["time"] if "time" not in ds.coords else [])
    if missing or "event_id" not in ds.attrs:
        what = ", ".join(missing + ([] if "event_id" in ds.attrs else ["the event_id attribute"]))
        raise InputError(f"{source}: cannot make a record of this result: it lacks {what}")
    return Record(event_id=str(ds.attrs["event_id"]), t=ds["time"].values, A=ds["A"].values, U=ds["U"].values,
                  dA=ds["dA"].values, noise_std=result_noise_std(ds.attrs, ds["A"].shape[1]),
                  yaw=ds["yaw"].values if "yaw" in ds.data_vars else None,
                  wind_distance=result_wind_distance(ds.attrs, ds["A"].shape[1]))


def result_wind_distance(attrs, n_sections: int) -> np.ndarray | None:
    """The result's distance from each section to its anemometer (attribute ``wind_distance_m``), m; None if absent."""
    return _per_section(attrs, "wind_distance_m", n_sections)


def result_noise_std(attrs, n_sections: int) -> np.ndarray | None:
    """The result's noise floor of A per section (attribute ``noise_std_m``), m; None if absent or malformed."""
    return _per_section(attrs, "noise_std_m", n_sections)


def _per_section(attrs, name: str, n_sections: int) -> np.ndarray | None:
    """A float attribute with one value per section, shape (n_sections,); None if absent or of another length."""
    value = attrs.get(name)
    if value is None:
        return None
    value = np.atleast_1d(np.asarray(value, dtype=float))
    return value if value.shape == (n_sections,) else None


class _Breach(Exception):
    """Internal: a format breach, turned into ResultFormatError with the file name."""


def _check_header(attrs: Mapping) -> None:
    fmt = attrs.get("format")
    if fmt != FORMAT:
        raise _Breach(f"not an identification result (format attribute is {fmt!r}, expected {FORMAT!r})")
    if "format_version" not in attrs:
        raise _Breach("no format_version attribute")
    version = attrs["format_version"]
    if isinstance(version, np.ndarray) and version.size == 1:
        version = version.item()
    if not isinstance(version, numbers.Integral) or isinstance(version, (bool, np.bool_)):
        raise _Breach(f"format_version is {version!r}, expected the integer {FORMAT_VERSION}")
    if version > FORMAT_VERSION:
        raise _Breach(f"format_version {version} is newer than this vivbench reads (up to {FORMAT_VERSION}); "
                      f"upgrade vivbench or re-run vivbench identify")
    if version < 1:
        raise _Breach(f"format_version {version} is not supported; this reader knows version {FORMAT_VERSION}")


def _check_layout(ds: xr.Dataset) -> None:
    for name in ds.data_vars:
        spec = VARIABLES.get(name)
        if spec is None:
            continue  # an extra variable: tolerated, not checked
        _check_spec(ds[name], name, spec)
    for name, spec in COORDINATES.items():
        if name in ds.dims or name in ds.coords:
            if name not in ds.coords:
                raise _Breach(f"missing coordinate {name}")
            _check_spec(ds.coords[name], name, spec)
    sizes = ds.sizes
    if "order" in sizes and sizes["order"] != _N_ORDERS:
        raise _Breach(f"dimension order has length {sizes['order']}, expected {_N_ORDERS} (orders 0..3)")
    if "equation" in sizes and "feature" in sizes and sizes.get("window", 0) > 0 \
            and sizes["feature"] != FEATURES_PER_SECTION * sizes["equation"]:
        coef = f"coef shape {ds['coef'].shape}" if "coef" in ds else f"{sizes['feature']} features"
        raise _Breach(f"{coef} does not match (window, equation, {FEATURES_PER_SECTION} x equation) "
                      f"with {sizes['equation']} equations")
    if "equation" in ds.coords and "section" in ds.coords \
            and ds["equation"].values.tolist() != ds["section"].values.tolist():
        raise _Breach(f"equation labels {ds['equation'].values.tolist()} differ from section labels "
                      f"{ds['section'].values.tolist()}")


def _check_spec(var: xr.DataArray, name: str, spec: VariableSpec) -> None:
    if var.dims != spec.dims:
        raise _Breach(f"{name} has dimensions {var.dims}, expected {spec.dims}")
    if var.dtype.kind not in spec.kind:
        raise _Breach(f"{name} has dtype {var.dtype}, expected {spec.dtype}")


# --------------------------------------------------------------------------------- docs


def markdown_table(table: Mapping[str, VariableSpec] | None = None) -> str:
    """The Markdown table of the variables (default) or coordinates, as in ``docs/formats.md``.

    Parameters
    ----------
    table : mapping, optional
        :data:`VARIABLES` (default) or :data:`COORDINATES`.

    Returns
    -------
    str
        One header line, one separator line and one row per entry, each ending in a newline.
    """
    table = VARIABLES if table is None else table
    rows = ["| name | dims | dtype | units | meaning |", "|---|---|---|---|---|"]
    for name, spec in table.items():
        meaning = spec.long_name.replace("{method}", "method")
        if not spec.required:
            meaning += "; optional"
        units = "-" if spec.units is None else f"`{spec.units}`"
        rows.append(f"| `{name}` | ({', '.join(spec.dims)}) | {spec.dtype} | {units} | {meaning} |")
    return "\n".join(rows) + "\n"


def markdown_attributes() -> str:
    """The Markdown table of the root attributes (:data:`ATTRIBUTES`), as in ``docs/formats.md``.

    Returns
    -------
    str
        One header line, one separator line and one row per attribute, each ending in a newline.
    """
    rows = ["| attribute | type | units | meaning |", "|---|---|---|---|"]
    for name, (kind, units, meaning) in ATTRIBUTES.items():
        rows.append(f"| `{name}` | {kind} | {f'`{units}`' if units else '-'} | {meaning} |")
    return "\n".join(rows) + "\n"
