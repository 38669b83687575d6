"""The event file format (vivbench.io): round trips, atomic writes, refusals."""

from __future__ import annotations

import json
import os
import pickle
import tempfile
from pathlib import Path

import h5py
import numpy as np
import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.helpers import assert_close
from vivbench import io
from vivbench.io import netcdf
from vivbench.core.terms import feature_names

# ----------------------------------------------------------------------- helpers


def _sections(n: int) -> tuple[str, ...]:
    return tuple(f"S{k + 1}" for k in range(n))


def _event_kwargs(seed: int = 0, *, n_wind: int = 64, n_acc: int = 100, n_t: int = 12, n_sec: int = 3, truth: bool = True, coef: bool = True):
    rng = np.random.default_rng(seed)
    kw = dict(
        event_id="event_007",
        start_time="2012-01-08T10:00:00Z",
        source="synthetic" if truth else "field",
        span_azimuth_deg=12.5,
        wind_time=np.arange(n_wind) / 32.0,
        u=rng.normal(8.0, 1.0, (n_wind, n_sec)).astype(np.float32),
        v=rng.normal(0.0, 1.0, (n_wind, n_sec)).astype(np.float32),
        w=rng.normal(0.0, 0.3, (n_wind, n_sec)).astype(np.float32),
        accel_time=0.01 + np.arange(n_acc) / 50.0,
        acc=rng.normal(0.0, 0.05, (n_acc, n_sec)).astype(np.float32),
        attrs={"campaign_seed": 1234, "notes": "unit test", "dt_clock": 0.5},
        sections=_sections(n_sec),
    )
    kw["u"][3, 0] = np.nan  # a data gap is a NaN value
    if truth:
        kw["truth"] = dict(
            time=np.arange(n_t) * 0.25,
            U=rng.uniform(5.0, 10.0, (n_t, n_sec)),
            A=rng.uniform(0.0, 0.3, (n_t, n_sec)),
            r=rng.normal(0.0, 1e-3, (n_t, n_sec, 4)),
            regime=rng.integers(1, 5, (n_t, n_sec)),
            config=json.dumps({"f1": 0.327, "phi": [0.707, 1.0, 0.707]}),
            tau=0.2,
        )
        if coef:
            names = feature_names(n_sec)
            kw["truth"].update(coef=rng.normal(size=(n_sec, len(names))), feature=names)
    return kw


def _assert_same_tree(actual: xr.DataTree, desired: xr.DataTree) -> None:
    """Same groups, attributes, variables, dimensions, dtypes and bit-identical values."""
    a_paths = sorted(n.path for n in actual.subtree)
    d_paths = sorted(n.path for n in desired.subtree)
    assert a_paths == d_paths, f"groups differ: {a_paths} vs {d_paths}"
    for path in d_paths:
        a_node, d_node = actual[path], desired[path]
        assert set(a_node.attrs) == set(d_node.attrs), f"{path}: attribute names {set(a_node.attrs)} vs {set(d_node.attrs)}"
        for key, value in d_node.attrs.items():
            got = a_node.attrs[key]
            assert isinstance(got, str) == isinstance(value, str) and got == value, f"{path} attr {key}: {got!r} vs {value!r}"
        a_vars = a_node.to_dataset(inherit=False).variables
        d_vars = d_node.to_dataset(inherit=False).variables
        assert set(a_vars) == set(d_vars), f"{path}: variables {set(a_vars)} vs {set(d_vars)}"
        for name, d_var in d_vars.items():
            a_var = a_vars[name]
            where = f"{path}/{name}"
            assert a_var.dims == d_var.dims, f"{where}: dims {a_var.dims} vs {d_var.dims}"
            assert a_var.dtype == d_var.dtype, f"{where}: dtype {a_var.dtype} vs {d_var.dtype}"
            assert a_var.attrs == d_var.attrs, f"{where}: attrs {a_var.attrs} vs {d_var.attrs}"
            a_val, d_val = a_var.values, d_var.values
            if d_val.dtype.kind in "fiu":
                bits = np.dtype(f"u{d_val.dtype.itemsize}")
                assert np.array_equal(a_val.view(bits), d_val.view(bits)), f"{where}: values differ bitwise"
            else:
                assert a_val.tolist() == d_val.tolist(), f"{where}: {a_val.tolist()} vs {d_val.tolist()}"


def _groups(tree: xr.DataTree) -> dict:
    return {node.path: node.to_dataset(inherit=False) for node in tree.subtree}


def _write_raw(groups: dict, path: Path) -> Path:
    """Write a (possibly broken) tree with xarray alone, bypassing validation."""
    xr.DataTree.from_dict(groups).to_netcdf(path, engine=io.NETCDF_ENGINE)
    return path


def _valid_file(tmp_path: Path, name: str = "event_007.nc", **kwargs) -> Path:
    return io.write_event(io.build_event(**_event_kwargs(**kwargs)), tmp_path / name)


def _refused(path: Path, *words: str) -> str:
    with pytest.raises(io.EventFormatError) as info:
        io.read_event(path)
    message = str(info.value)
    assert message.startswith(f"{path}: "), f"message does not start with the file name: {message!r}"
    assert "\n" not in message, f"message is not one line: {message!r}"
    for word in words:
        assert word in message, f"{word!r} not in {message!r}"
    return message


def _open_paths() -> list[str]:
    fd_dir = Path("/proc/self/fd")
    out = []
    for fd in fd_dir.iterdir():
        try:
            out.append(os.readlink(fd))
        except OSError:
            pass
    return out


# -------------------------------------------------------------------- round trip


@pytest.mark.parametrize("truth", [True, False], ids=["with-truth", "without-truth"])
def test_round_trip_is_identical(tmp_path, truth):
    tree = io.build_event(**_event_kwargs(truth=truth))
    path = io.write_event(tree, tmp_path / "event_007.nc")
    back = io.read_event(path)
    _assert_same_tree(back, tree)
    assert ("truth" in back.children) == truth, "truth group presence changed"


def test_layout_attributes_and_units(tmp_path):
    tree = io.build_event(**_event_kwargs())
    back = io.read_event(io.write_event(tree, tmp_path / "event_007.nc"))
    assert back.attrs["format"] == io.FORMAT and back.attrs["format_version"] == io.FORMAT_VERSION, f"root attrs {back.attrs}"
    for path in ("/wind", "/accel", "/truth"):
        for name, var in back[path].to_dataset(inherit=False).variables.items():
            assert "long_name" in var.attrs, f"{path}/{name} lacks long_name"
            if var.dtype.kind != "U":
                assert "units" in var.attrs, f"{path}/{name} lacks units"
    assert back["truth"].attrs["config_json"] == _event_kwargs()["truth"]["config"], "config_json not stored verbatim"
    assert back["truth"]["coef"].attrs["units"] == io.COEF_UNITS, "coef units"
    assert back["truth"]["equation"].values.tolist() == ["S1", "S2", "S3"], "coef equation labels"


def test_event_arrays_match_inputs(tmp_path):
    kw = _event_kwargs()
    arrays = io.event_arrays(io.read_event(io.write_event(io.build_event(**kw), tmp_path / "e.nc")))
    assert arrays["sections"] == ("S1", "S2", "S3"), f"sections {arrays['sections']}"
    for key in ("wind_time", "u", "v", "w", "accel_time", "acc"):
        assert isinstance(arrays[key], np.ndarray), f"{key} is not a numpy array"
        np.testing.assert_array_equal(arrays[key], kw[key], err_msg=key)
    for key in ("U", "A", "r", "regime", "coef"):
        np.testing.assert_array_equal(arrays[key], kw["truth"][key], err_msg=key)
    np.testing.assert_array_equal(arrays["truth_time"], kw["truth"]["time"], err_msg="truth_time")
    assert arrays["feature"] == tuple(kw["truth"]["feature"]), "feature names"


def test_build_then_rebuild_from_event_arrays_is_identical():
    kw = _event_kwargs(truth=False)
    tree = io.build_event(**kw)
    arrays = io.event_arrays(tree)
    again = io.build_event(
        **{k: kw[k] for k in ("event_id", "start_time", "source", "span_azimuth_deg", "attrs")},
        **{k: arrays[k] for k in ("wind_time", "u", "v", "w", "accel_time", "acc")},
        sections=arrays["sections"],
    )
    _assert_same_tree(again, tree)


_float_values = st.sampled_from([np.float32, np.float64])


@settings(max_examples=25, deadline=None)
@given(
    n_sec=st.integers(1, 4),
    n_wind=st.integers(2, 40),
    n_acc=st.integers(2, 40),
    n_t=st.integers(2, 8),
    rate_factor=st.floats(0.93, 1.07),
    offset=st.floats(-5.0, 5.0),
    dtype=_float_values,
    with_truth=st.booleans(),
    data=st.data(),
)
def test_round_trip_property(n_sec, n_wind, n_acc, n_t, rate_factor, offset, dtype, with_truth, data):
    """Any valid event, of any size and with any sensor values (NaN, inf included), reads back bit for bit."""
    elements = st.floats(width=8 * np.dtype(dtype).itemsize, allow_nan=True, allow_infinity=True)
    sensor = lambda n: data.draw(hnp.arrays(dtype, (n, n_sec), elements=elements))  # noqa: E731
    truth = None
    if with_truth:
        finite = st.floats(-1e6, 1e6)
        truth = dict(
            time=np.arange(n_t) * 0.5,
            U=data.draw(hnp.arrays(np.float64, (n_t, n_sec), elements=finite)),
            A=data.draw(hnp.arrays(np.float64, (n_t, n_sec), elements=finite)),
            r=data.draw(hnp.arrays(np.float64, (n_t, n_sec, 4), elements=finite)),
            regime=data.draw(hnp.arrays(np.int8, (n_t, n_sec), elements=st.integers(1, 4))),
            config="{}",
        )
    tree = io.build_event(
        event_id="ev-1",
        start_time="2020-02-29T23:59:59.500000+00:00",
        source="synthetic",
        span_azimuth_deg=data.draw(st.floats(0.0, 360.0)),
        wind_time=offset + np.arange(n_wind) / (32.0 * rate_factor),
        u=sensor(n_wind),
        v=sensor(n_wind),
        w=sensor(n_wind),
        accel_time=offset + np.arange(n_acc) / (50.0 * rate_factor),
        acc=sensor(n_acc),
        truth=truth,
        sections=_sections(n_sec),
    )
    with tempfile.TemporaryDirectory() as tmp:
        back = io.read_event(io.write_event(tree, Path(tmp) / "ev-1.nc"))
    _assert_same_tree(back, tree)


def test_big_event_compresses_and_round_trips(tmp_path):
    """A 40 min event (76800 x 3 wind, 120000 x 3 accel samples) is stored compressed and reads back bit for bit."""
    rng = np.random.default_rng(3)
    n_wind, n_acc = 76800, 120000
    quantised = lambda x, step: (np.round(x / step) * step).astype(np.float32)  # noqa: E731
    tree = io.build_event(
        event_id="long",
        start_time="2012-01-08T10:00:00Z",
        source="field",
        span_azimuth_deg=10.0,
        wind_time=np.arange(n_wind) / 32.0,
        u=quantised(rng.normal(8.0, 0.6, (n_wind, 3)), 0.01),
        v=quantised(rng.normal(0.0, 0.5, (n_wind, 3)), 0.01),
        w=quantised(rng.normal(0.0, 0.3, (n_wind, 3)), 0.01),
        accel_time=np.arange(n_acc) / 50.0,
        acc=quantised(rng.normal(0.0, 0.05, (n_acc, 3)), 9.81 * 4 / 65536),
    )
    path = io.write_event(tree, tmp_path / "long.nc")
    raw_bytes = sum(node.to_dataset(inherit=False).nbytes for node in tree.subtree)
    assert path.stat().st_size < 0.5 * raw_bytes, f"file {path.stat().st_size} B vs raw {raw_bytes} B: not compressed"
    _assert_same_tree(io.read_event(path), tree)


# ------------------------------------------------------------------- build checks


@pytest.mark.parametrize(
    "change, words",
    [
        (dict(u=np.zeros((63, 3), np.float32)), ["u must have shape", "(64, 3)"]),
        (dict(acc=np.zeros((100, 2), np.float32)), ["acc must have shape"]),
        (dict(start_time="2012-01-08 10:00:00"), ["UTC"]),
        (dict(start_time="yesterday"), ["not an ISO 8601"]),
        (dict(start_time="2012-01-08T10:00:00+01:00"), ["UTC"]),
        (dict(source="lab"), ["source 'lab'", "synthetic, field"]),
        (dict(event_id="a.b"), ["event_id 'a.b'"]),
        (dict(attrs={"flag": True}), ["'flag'", "str, int or float"]),
        (dict(attrs={"list": [1, 2]}), ["'list'"]),
        (dict(attrs={"source": "x"}), ["'source'", "replace"]),
        (dict(attrs={"_FillValue": 1}), ["'_FillValue'"]),
        (dict(sections=("A", "B", "C")), ["labels are ['A', 'B', 'C']"]),
        (dict(wind_time=np.arange(64) / 20.0), ["/wind/time", "sampling rate 20 Hz", "nominal 32 Hz"]),
        (dict(accel_time=np.r_[0.0, np.arange(99) / 50.0]), ["/accel/time", "repeats"]),
    ],
)
def test_build_event_refuses_bad_arguments(change, words):
    kw = _event_kwargs(truth=False)
    kw.update(change)
    with pytest.raises(ValueError) as info:
        io.build_event(**kw)
    for word in words:
        assert word in str(info.value), f"{word!r} not in {str(info.value)!r}"


@pytest.mark.parametrize(
    "change, words",
    [
        (dict(regime=np.full((12, 3), 5)), ["/truth/regime", "outside 1..4"]),
        (dict(r=np.zeros((12, 3, 3))), ["truth['r'] must have shape"]),
        (dict(config=b"{}"), ["truth['config']"]),
        (dict(config="{not json"), ["config_json is not valid JSON"]),
        (dict(tau=1.5), ["tau"]),
        (dict(extra=1), ["unknown truth keys ['extra']"]),
        (dict(feature=["x"] * 69), ["distinct"]),
        (dict(coef=np.zeros((3, 5))), ["truth['coef'] must have shape"]),
    ],
)
def test_build_event_refuses_bad_truth(change, words):
    kw = _event_kwargs()
    kw["truth"].update(change)
    with pytest.raises(ValueError) as info:
        io.build_event(**kw)
    for word in words:
        assert word in str(info.value), f"{word!r} not in {str(info.value)!r}"


def test_build_event_keeps_sensor_dtype_and_stores_float64_times():
    kw = _event_kwargs(truth=False)
    kw["acc"] = kw["acc"].astype(np.float64)
    kw["wind_time"] = kw["wind_time"].astype(np.float32)
    tree = io.build_event(**kw)
    assert tree["wind"]["u"].dtype == np.float32, "float32 sensor data must stay float32"
    assert tree["accel"]["acc"].dtype == np.float64, "float64 sensor data must stay float64"
    assert tree["wind"]["time"].dtype == np.float64, "times are stored as float64"


def test_accepted_unit_spellings_and_field_truth(tmp_path):
    tree = io.build_event(**_event_kwargs())
    groups = _groups(tree)
    groups["/"].attrs["source"] = "field"  # a field event may carry a truth (e.g. a reference model)
    groups["/wind"]["u"].attrs["units"] = "m s-1"
    groups["/accel"]["acc"].attrs["units"] = "m s-2"
    path = _write_raw(groups, tmp_path / "spelled.nc")
    back = io.read_event(path)
    assert back["wind"]["u"].attrs["units"] == "m s-1", "alternative spelling must be kept as written"
    groups["/accel"]["acc"].attrs["units"] = "m/s2"
    io.read_event(_write_raw(groups, tmp_path / "spelled2.nc"))


# -------------------------------------------------------------------- atomic write


def _directory_state(directory: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


def test_write_failure_mid_write_leaves_old_file_and_no_temp(tmp_path, monkeypatch):
    target = _valid_file(tmp_path, seed=1)
    before = _directory_state(tmp_path)
    original = xr.DataTree.to_netcdf
    seen = []

    def half_write_then_fail(self, filepath, *args, **kwargs):
        original(self, filepath, *args, **kwargs)
        seen.append(Path(filepath))
        assert Path(filepath).exists(), "the temporary file should exist before the simulated failure"
        raise OSError("simulated: disk full")

    monkeypatch.setattr(xr.DataTree, "to_netcdf", half_write_then_fail)
    with pytest.raises(OSError, match="simulated"):
        io.write_event(io.build_event(**_event_kwargs(seed=2)), target)
    assert len(seen) == 1, "to_netcdf was not called"
    temp = seen[0]
    assert temp.parent == tmp_path, f"temporary file {temp} is not in the target directory"
    assert temp != target, "wrote directly to the target"
    assert not temp.match("*.nc"), f"temporary name {temp.name} is matched by *.nc"
    assert _directory_state(tmp_path) == before, "directory changed after a failed write"


def test_write_failure_at_rename_leaves_old_file_and_no_temp(tmp_path, monkeypatch):
    target = _valid_file(tmp_path, seed=1)
    before = _directory_state(tmp_path)

    def failing_replace(src, dst):
        raise PermissionError("simulated: rename refused")

    monkeypatch.setattr(netcdf.os, "replace", failing_replace)
    with pytest.raises(PermissionError, match="simulated"):
        io.write_event(io.build_event(**_event_kwargs(seed=2)), target)
    assert _directory_state(tmp_path) == before, "directory changed after a failed rename"


def test_write_replaces_existing_file_and_creates_directories(tmp_path):
    target = tmp_path / "a" / "b" / "event_007.nc"
    io.write_event(io.build_event(**_event_kwargs(seed=1)), target)
    new = io.build_event(**_event_kwargs(seed=2))
    assert io.write_event(new, target) == target, "write_event returns the path"
    _assert_same_tree(io.read_event(target), new)
    assert [p.name for p in target.parent.iterdir()] == ["event_007.nc"], "stray files left"


def test_write_refuses_invalid_tree_and_writes_nothing(tmp_path):
    groups = _groups(io.build_event(**_event_kwargs()))
    groups["/"].attrs["format_version"] = 2
    target = tmp_path / "sub" / "event_007.nc"
    with pytest.raises(io.EventFormatError, match=r"^\S*event_007\.nc: format_version 2 is not supported"):
        io.write_event(xr.DataTree.from_dict(groups), target)
    assert not (tmp_path / "sub").exists(), "nothing may be created for an invalid event"


def test_read_leaves_no_open_handle(tmp_path):
    if not Path("/proc/self/fd").is_dir():
        pytest.skip("needs /proc to list open files")
    good = _valid_file(tmp_path)
    io.read_event(good)
    bad = tmp_path / "bad.nc"
    with h5py.File(_valid_file(tmp_path, name="bad.nc"), "r+") as f:
        f["accel/acc"].attrs["units"] = "g"
    with pytest.raises(io.EventFormatError):
        io.read_event(bad)
    still_open = [p for p in _open_paths() if p in (str(good), str(bad))]
    assert not still_open, f"files still open after read_event: {still_open}"


# ------------------------------------------------------------------ broken files


def _edit(path: Path, edit) -> Path:
    with h5py.File(path, "r+") as f:
        edit(f)
    return path


def _set_time(group: str, change):
    def edit(f):
        t = f[f"{group}/time"][...]
        f[f"{group}/time"][...] = change(t)

    return edit


def _swap(t):
    t = t.copy()
    t[[5, 6]] = t[[6, 5]]
    return t


def _duplicate(t):
    t = t.copy()
    t[6] = t[5]
    return t


def _nan_time(t):
    t = t.copy()
    t[7] = np.nan
    return t


def _shorten_u(f):
    """Replace /wind/u by an array 4 samples short, still attached to the time and section dimensions."""
    old = f["wind/u"]
    data, attrs = old[...], {k: v for k, v in old.attrs.items() if k != "DIMENSION_LIST"}
    del f["wind/u"]
    new = f["wind"].create_dataset("u", data=data[:-4])
    for k, v in attrs.items():
        new.attrs[k] = v
    new.dims[0].attach_scale(f["wind/time"])
    new.dims[1].attach_scale(f["wind/section"])


@pytest.mark.parametrize(
    "edit, words",
    [
        (lambda f: f.__delitem__("accel"), ["missing group /accel"]),
        (lambda f: f.__delitem__("wind/v"), ["missing variable /wind/v"]),
        (lambda f: f.__delitem__("truth/r"), ["missing variable /truth/r"]),
        (lambda f: f["accel/acc"].attrs.__setitem__("units", "g"), ["/accel/acc has units 'g'", "'m/s^2'"]),
        (lambda f: f["wind/u"].attrs.__delitem__("units"), ["/wind/u has no units"]),
        (lambda f: f["wind/time"].attrs.__setitem__("units", "ms"), ["/wind/time has units 'ms'"]),
        (_set_time("wind", _swap), ["/wind/time is not strictly increasing", "goes back"]),
        (_set_time("accel", _duplicate), ["/accel/time is not strictly increasing", "repeats"]),
        (_set_time("wind", _nan_time), ["/wind/time[7] is nan"]),
        (_set_time("accel", lambda t: t * 2.0), ["/accel/time", "sampling rate 25 Hz", "nominal 50 Hz"]),
        (_set_time("wind", lambda t: t / 1.2), ["/wind/time", "sampling rate 38.4 Hz"]),
        (_set_time("truth", lambda t: t[::-1].copy()), ["/truth/time is not strictly increasing"]),
        (_shorten_u, ["/wind/u has shape (60, 3)", "/wind/time has 64"]),
        (lambda f: f["wind/section"].__setitem__(1, "SX"), ["/wind/section labels are ['S1', 'SX', 'S3']"]),
        (lambda f: f["accel/section"].__setitem__(2, "S4"), ["/accel/section labels are ['S1', 'S2', 'S4']"]),
        (lambda f: f["truth/regime"].__setitem__((0, 0), 0), ["/truth/regime has values [0] outside 1..4"]),
        (lambda f: f["truth/order"].__setitem__(3, 4), ["/truth/order is [0, 1, 2, 4]"]),
        (lambda f: f.attrs.__setitem__("format", "netcdf-thing"), ["format is 'netcdf-thing'", "'vivbench-event'"]),
        (lambda f: f.attrs.__setitem__("format_version", 2), ["format_version 2 is not supported"]),
        (lambda f: f.attrs.__delitem__("start_time"), ["missing root attribute start_time"]),
        (lambda f: f.attrs.__setitem__("start_time", "2012-13-45T00:00:00Z"), ["start_time", "not an ISO 8601"]),
        (lambda f: f.attrs.__setitem__("source", "model"), ["source 'model'"]),
        (lambda f: f.attrs.__setitem__("span_azimuth_deg", np.nan), ["span_azimuth_deg"]),
        (lambda f: f.attrs.__setitem__("source", np.array(["a", "b"], dtype=object)), ["source"]),
        (lambda f: f["truth"].attrs.__setitem__("config_json", "{not json"), ["config_json is not valid JSON"]),
        (lambda f: f["truth/regime"].attrs.__setitem__("units", "m"), ["/truth/regime has units 'm'", "'1'"]),
    ],
    ids=[
        "missing-group",
        "missing-variable",
        "missing-truth-variable",
        "wrong-units",
        "no-units",
        "wrong-time-units",
        "non-monotonic-time",
        "duplicated-time",
        "nan-time",
        "rate-too-low",
        "rate-too-high",
        "truth-time-decreasing",
        "wrong-shape",
        "wrong-section-labels",
        "sections-differ-between-groups",
        "regime-out-of-range",
        "wrong-order-coordinate",
        "wrong-format",
        "wrong-format-version",
        "missing-root-attribute",
        "bad-start-time",
        "bad-source",
        "nan-azimuth",
        "array-attribute",
        "truth-config-not-json",
        "regime-wrong-units",
    ],
)
def test_broken_file_is_refused(tmp_path, edit, words):
    path = _edit(_valid_file(tmp_path), edit)
    _refused(path, *words)


def test_truth_of_another_generator_is_read(tmp_path):
    """Validation needs only time, section, U, A, r and regime from /truth (issue 13): no
    config_json, a regime without units and no coef are read; the identification's reading
    (truth=False) does not even look at a truth that lacks r."""
    def strip(f):
        del f["truth"].attrs["config_json"]
        del f["truth/regime"].attrs["units"]

    back = io.read_event(_edit(_valid_file(tmp_path, coef=False), strip))
    assert "config_json" not in back["truth"].attrs and back["truth"]["regime"].values.min() >= 1
    partial = _edit(_valid_file(tmp_path, name="partial.nc"), lambda f: f.__delitem__("truth/r"))
    _refused(partial, "missing variable /truth/r")
    tree = io.read_event(partial, truth=False)
    assert "truth" not in tree.children and set(tree.children) == {"wind", "accel"}


@pytest.mark.parametrize(
    "group, change, words",
    [
        ("/wind", lambda ds: ds.assign(u=ds["u"].isel(section=0)), ["/wind/u has dimensions ('time',)", "('time', 'section')"]),
        ("/wind", lambda ds: ds.assign(u=ds["u"].transpose()), ["/wind/u has dimensions ('section', 'time')"]),
        ("/accel", lambda ds: ds.assign(acc=ds["acc"].astype(np.int16)), ["/accel/acc has dtype int16"]),
        ("/accel", lambda ds: ds.isel(time=slice(0, 1)), ["/accel/time has 1 sample(s)"]),
        ("/wind", lambda ds: ds.assign_coords(time=ds["time"].astype(np.float32)), ["/wind/time has dtype float32"]),
        ("/wind", lambda ds: ds.drop_vars("section"), ["missing coordinate /wind/section"]),
        ("/truth", lambda ds: ds.isel(section=[0, 1]), ["/truth/section labels are ['S1', 'S2']", "as in /wind/section"]),
        ("/truth", lambda ds: ds.assign(regime=ds["regime"].astype(np.float64)), ["/truth/regime has dtype float64"]),
    ],
    ids=["1d-variable", "transposed", "integer-data", "one-sample", "float32-time", "no-section-coordinate", "truth-sections", "float-regime"],
)
def test_broken_layout_written_by_xarray_is_refused(tmp_path, group, change, words):
    groups = _groups(io.build_event(**_event_kwargs()))
    groups[group] = change(groups[group])
    path = _write_raw(groups, tmp_path / "event_007.nc")
    _refused(path, *words)


def test_not_an_event_file_is_refused(tmp_path):
    text = tmp_path / "notes.nc"
    text.write_text("this is not HDF5\n")
    _refused(text, "cannot be read as NetCDF-4/HDF5")
    empty = tmp_path / "empty.nc"
    empty.touch()
    _refused(empty, "cannot be read as NetCDF-4/HDF5")
    plain = tmp_path / "plain.nc"
    with h5py.File(plain, "w") as f:
        f["x"] = np.arange(3)
    _refused(plain, "missing root attribute format")
    _refused(tmp_path / "absent.nc", "no such file")
    (tmp_path / "dir.nc").mkdir()
    _refused(tmp_path / "dir.nc", "is a directory")


def test_field_event_without_truth_and_truth_without_coef(tmp_path):
    io.read_event(_valid_file(tmp_path, name="field.nc", truth=False))
    back = io.read_event(_valid_file(tmp_path, name="nocoef.nc", coef=False))
    assert "coef" not in back["truth"].data_vars, "coef appeared from nowhere"


def test_rate_tolerance_is_ten_percent():
    for factor, ok in ((1.09, True), (0.91, True), (1.12, False), (0.88, False)):
        kw = _event_kwargs(truth=False)
        kw["accel_time"] = np.arange(100) / (50.0 * factor)
        if ok:
            io.build_event(**kw)
        else:
            with pytest.raises(io.EventFormatError, match="sampling rate"):
                io.build_event(**kw)


def test_rate_uses_median_step_so_gaps_are_allowed():
    kw = _event_kwargs(truth=False)
    t = np.arange(100) / 50.0
    t[60:] += 30.0  # a 30 s hole in the record: times stay authoritative
    kw["accel_time"] = t
    tree = io.build_event(**kw)
    assert_close(np.median(np.diff(tree["accel"]["time"].values)), 1 / 50.0, what="median step")


# ---------------------------------------------------------------------- small API


def test_error_message_and_pickling():
    err = io.EventFormatError("event_007.nc", "line one\nline two")
    assert str(err) == "event_007.nc: line one line two", f"got {str(err)!r}"
    assert isinstance(err, ValueError), "EventFormatError must be a ValueError"
    again = pickle.loads(pickle.dumps(err))
    assert str(again) == str(err) and again.filename == "event_007.nc", f"pickled: {again!r}"


def test_validate_event_names_memory_by_default():
    groups = _groups(io.build_event(**_event_kwargs(truth=False)))
    del groups["/accel"]
    with pytest.raises(io.EventFormatError, match=r"^<memory>: missing group /accel$"):
        io.validate_event(xr.DataTree.from_dict(groups))


def test_list_events(tmp_path):
    for name in ("b.nc", "a.nc", "a.identify.nc", "report.clusters.nc", ".a.nc.tmp-12-ab", ".hidden.nc", "notes.txt"):
        (tmp_path / name).touch()
    (tmp_path / "dir.nc").mkdir()
    found = [p.name for p in io.list_events(tmp_path)]
    assert found == ["a.nc", "b.nc"], f"list_events gave {found}"
    with pytest.raises(FileNotFoundError):
        io.list_events(tmp_path / "absent")
