"""File formats: each schema has one owner module, a typed reader and a document that cannot drift."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import xarray as xr

import vivbench
from vivbench.analysis.identify import IdentifyConfig, identify_event
from vivbench.io import event as event_format
from vivbench.io import result as result_format
from vivbench.io.netcdf import write_netcdf_atomic
from tests.helpers import REPO, assert_close

DOC = REPO / "docs" / "formats.md"
PACKAGE = Path(vivbench.__file__).resolve().parent


@pytest.fixture(scope="module")
def identified(short_event, tmp_path_factory):
    """The short event identified in memory and written with write_result: (dataset, file)."""
    ds = identify_event(short_event, IdentifyConfig(), source="short.nc")
    path = result_format.write_result(ds, tmp_path_factory.mktemp("formats"))
    return ds, path


def _documented_names() -> set[str]:
    return set(re.findall(r"`([A-Za-z_][A-Za-z0-9_]*)`", DOC.read_text(encoding="utf-8")))


# ------------------------------------------------------------------------------ docs


def test_doc_holds_the_generated_result_tables():
    text = DOC.read_text(encoding="utf-8")
    for table in (result_format.markdown_table(), result_format.markdown_table(result_format.COORDINATES),
                  result_format.markdown_attributes()):
        assert table in text, f"docs/formats.md is out of date; regenerate this table from vivbench.io.result:\n{table}"


def test_every_result_variable_written_is_in_the_schema_and_documented(identified):
    ds, _path = identified
    documented = _documented_names()
    schema = set(result_format.VARIABLES) | set(result_format.COORDINATES) | set(result_format.ATTRIBUTES)
    for name in [*ds.data_vars, *ds.coords]:
        assert name in schema, f"identify_event writes {name!r}, which vivbench.io.result does not declare"
        assert name in documented, f"identify_event writes {name!r}, which docs/formats.md does not document"
    for name, spec in result_format.VARIABLES.items():
        if name in ds:
            assert ds[name].dims == spec.dims, f"{name}: written dims {ds[name].dims}, schema {spec.dims}"
            assert str(ds[name].dtype) == spec.dtype, f"{name}: written dtype {ds[name].dtype}, schema {spec.dtype}"
            assert ds[name].attrs["units"] == spec.units, f"{name}: units {ds[name].attrs['units']!r}"
    for name in ds.attrs:
        # quality_* attributes are listed in their own table of the doc, not in the schema's
        assert name.startswith("quality_") or name in result_format.ATTRIBUTES, \
            f"identify_event writes attribute {name!r}, which vivbench.io.result does not declare"
        assert name in documented, f"identify_event writes attribute {name!r}, not in docs/formats.md"


def test_doc_lists_the_event_and_campaign_model_variables(short_event):
    documented = _documented_names()
    for group in ("wind", "accel", "truth"):
        ds = short_event[group].to_dataset()
        for name in [*ds.data_vars, *ds.coords, *ds.attrs]:
            assert name in documented, f"event group /{group}: {name!r} is not in docs/formats.md"
    for name in ("format", "format_version", "event_id", "start_time", "source", "span_azimuth_deg"):
        assert name in documented
    for name in ("coef_bootstrap", "agreement", "robust", "window_all", "bootstrap", "events", "enough_data",
                 "model_config_json", "derivative_json"):
        assert name in documented, f"campaign model: {name!r} is not in docs/formats.md"


def test_result_format_constants_are_the_files():
    assert result_format.FORMAT == "vivbench-identify" and result_format.FORMAT_VERSION == 1


def test_only_the_owners_open_event_and_result_files():
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel.startswith("io/"):
            continue
        text = path.read_text(encoding="utf-8")
        for pattern in ('"vivbench-identify"', "open_datatree(", "h5py.File(", "load_datatree("):
            if pattern in text:
                offenders.append(f"{rel}: {pattern}")
    assert not offenders, f"open event/result files through vivbench.io.event / vivbench.io.result: {offenders}"


# ---------------------------------------------------------------------------- writer


def test_write_result_is_byte_identical_to_the_plain_writer(identified, tmp_path):
    ds, path = identified
    plain = write_netcdf_atomic(ds, tmp_path / path.name)
    assert path.name == f"{ds.attrs['event_id']}.identify.nc"
    assert plain.read_bytes() == path.read_bytes()
    with pytest.raises(ValueError, match="not an identification result"):
        result_format.write_result(ds.assign_attrs(format="vivbench-pooled"), tmp_path / "x")
    assert not (tmp_path / "x").exists() or not list((tmp_path / "x").iterdir())


def test_read_result_round_trip_and_subset(identified):
    ds, path = identified
    back = result_format.read_result(path)
    assert set(back.data_vars) == set(ds.data_vars)
    xr.testing.assert_identical(back.drop_encoding(), ds)
    sub = result_format.read_result(path, ["A", "U"], optional=["amplitude_snr", "inclusion"])
    assert list(sub.data_vars) == ["amplitude_snr", "A", "U"]
    assert set(sub.coords) == set(ds.coords) and list(sub.attrs) == list(back.attrs)
    only_coords = result_format.read_result(path, ())
    assert not only_coords.data_vars and only_coords["time"].size == ds["time"].size


# ---------------------------------------------------------------------------- reader


def _edited(ds: xr.Dataset, tmp_path: Path, edit) -> Path:
    path = tmp_path / "E900.identify.nc"
    write_netcdf_atomic(edit(ds.copy()), path)
    return path


def _refused(path, *fragments) -> str:
    with pytest.raises(ValueError) as info:
        result_format.read_result(path)
    msg = str(info.value)
    assert isinstance(info.value, result_format.ResultFormatError)
    assert "\n" not in msg, f"not one line: {msg!r}"
    assert msg.startswith(f"{path}: "), f"does not start with the file name: {msg!r}"
    for fragment in fragments:
        assert fragment in msg, f"{fragment!r} not in {msg!r}"
    return msg


@pytest.mark.parametrize("edit, fragments", [
    (lambda ds: ds.assign_attrs(format="vivbench-pooled"), ["not an identification result", "'vivbench-pooled'"]),
    (lambda ds: ds.assign_attrs(format_version=2), ["format_version 2 is newer", "upgrade vivbench"]),
    (lambda ds: ds.assign_attrs(format_version=0), ["format_version 0 is not supported"]),
    (lambda ds: ds.assign_attrs(format_version="1"), ["format_version is '1'"]),
    (lambda ds: ds.drop_vars("dA"), ["lacks the variable dA"]),
    (lambda ds: ds.drop_vars(["regime", "coef"]), ["lacks the variables coef, regime"]),
    (lambda ds: ds.isel(feature=slice(0, 22)), ["coef shape", "23 x equation"]),
    (lambda ds: ds.assign(order_rms=ds["order_rms"].transpose("window", "order", "equation")),
     ["order_rms has dimensions ('window', 'order', 'equation')"]),
    (lambda ds: ds.isel(order=slice(0, 3)), ["order has length 3"]),
    (lambda ds: ds.assign(regime=ds["regime"].astype("float64")), ["regime has dtype float64, expected int8"]),
])
def test_read_result_refuses_a_broken_file(identified, tmp_path, edit, fragments):
    ds, _path = identified
    _refused(_edited(ds, tmp_path, edit), *fragments)


def test_read_result_refuses_missing_and_foreign_files(identified, tmp_path):
    _refused(tmp_path / "nothing.identify.nc", "no such result file")
    text = tmp_path / "text.identify.nc"
    text.write_text("not netcdf\n")
    _refused(text, "cannot be read as a NetCDF-4 result")
    ds, _path = identified
    path = _edited(ds, tmp_path, lambda d: d)
    with pytest.raises(result_format.ResultFormatError, match=r"lacks the variable nope$"):
        result_format.read_result(path, ["A", "nope"])


# ----------------------------------------------------------------------------- event


def test_event_reader_refuses_a_newer_version(short_event, tmp_path):
    tree = short_event.copy()
    tree.attrs = {**tree.attrs, "format_version": 2}
    path = tmp_path / "E901.nc"
    write_netcdf_atomic(tree, path)
    for reader in (event_format.read_event, event_format.read_event_summary):
        with pytest.raises(event_format.EventFormatError) as info:
            reader(path)
        msg = str(info.value)
        assert msg.startswith(f"{path}: format_version 2 is not supported") and "upgrade vivbench" in msg, msg
        assert "\n" not in msg


def test_event_summary_and_peek(short_event, tmp_path):
    path = event_format.write_event(short_event, tmp_path / "E902.nc")
    summary = event_format.read_event_summary(path)
    assert summary.attrs == dict(event_format.read_event(path).attrs)
    assert summary.truth is not None and set(summary.truth.data_vars) >= {"U", "A", "r", "regime"}
    t = short_event["accel"]["time"].values
    assert_close(summary.duration_s, float(t[-1] - t[0]))
    assert event_format.peek_event_id(path) == short_event.attrs["event_id"]
    assert event_format.peek_event_id(tmp_path / "missing.nc") is None
    with pytest.raises(event_format.EventFormatError, match=r"missing\.nc: no such event file$"):
        event_format.read_event_summary(tmp_path / "missing.nc")
