"""Field import with sensor positions along the span and anemometers in their own formats."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.helpers import REPO, assert_close
from vivbench.analysis.identify import identify_event
from vivbench.cli import main
from vivbench.io import event_arrays
from vivbench.io.field_wind import span_weights, to_east_north_up
from vivbench.io.fieldimport import import_event
from tests.io.test_field_import_rates import CONFIG


def _write(tree, out, *, anemometers: dict, wind_head: str = "", rule: str | None = None, span: float = 1000.0,
           positions=(250.0, 500.0, 750.0)):
    """Acceleration of every section in one CSV; each anemometer a CSV of the given event section's wind (m/s).

    ``anemometers``: name -> (section index of the event whose wind it records, position m, extra TOML lines).
    """
    arr = {k: np.asarray(v, dtype=np.float64) if k != "sections" else v for k, v in event_arrays(tree).items()}
    acc = {"time": arr["accel_time"], **{f"acc_S{i + 1}": arr["acc"][:, i] for i in range(arr["acc"].shape[1])}}
    pd.DataFrame(acc).to_csv(out / "accel.csv", index=False)
    lines = [f'event_id = "P1"', f'start_time = "{tree.attrs["start_time"]}"',
             f"span_azimuth_deg = {float(tree.attrs['span_azimuth_deg'])!r}", f"span_length_m = {span!r}"]
    lines += [f'wind_rule = "{rule}"'] if rule else []
    lines += ["", "[wind]", 'units = "m/s"', wind_head, ""]
    for name, (i, pos, extra, frame) in anemometers.items():
        frame = frame if frame is not None else {"time": arr["wind_time"], "u": arr["u"][:, i], "v": arr["v"][:, i],
                                                 "w": arr["w"][:, i]}
        pd.DataFrame(frame).to_csv(out / f"wind_{name}.csv", index=False)
        lines += [f"[wind.{name}]", f'file = "wind_{name}.csv"', f"position_m = {pos!r}", *extra, ""]
    lines += ["[accel]", 'file = "accel.csv"', 'units = "m/s^2"', ""]
    for k, pos in enumerate(positions):
        lines += [f"[accel.S{k + 1}]", f'acc = "acc_S{k + 1}"', f"position_m = {pos!r}", ""]
    mapping = out / "mapping.toml"
    mapping.write_text("\n".join(lines))
    return mapping


ENU = ['u = "u"', 'v = "v"', 'w = "w"']


def test_one_mid_span_anemometer_for_three_sections_imports_and_identifies(short_event, tmp_path):
    mapping = _write(short_event, tmp_path, anemometers={"mid": (1, 500.0, ENU, None)})
    tree = import_event(mapping)
    a, b = event_arrays(tree), event_arrays(short_event)
    b = {k: np.asarray(b[k], dtype=np.float64) for k in ("u", "v", "acc")}
    assert list(a["sections"]) == ["S1", "S2", "S3"]
    for j in range(3):  # every section gets the mid-span wind
        np.testing.assert_array_equal(a["u"][:, j], b["u"][:, 1])
    np.testing.assert_array_equal(a["acc"], b["acc"])
    assert [tree.attrs[f"wind_distance_m_S{k}"] for k in (1, 2, 3)] == [250.0, 0.0, 250.0]
    assert tree.attrs["import_wind_rule"] == "nearest" and tree.attrs["import_anemometer_position_m_mid"] == 500.0
    res = identify_event(tree, CONFIG)
    ref = identify_event(short_event, CONFIG)
    assert res.sizes["window"] == ref.sizes["window"] > 0 and res.sizes["section"] == 3
    assert np.isfinite(res["U"].values).mean() > 0.5
    # The acceleration is the event's own, so is the envelope.
    assert_close(res["A"].values, ref["A"].values, rtol=1e-9, atol=1e-12, reason="float32 event vs float64 import")
    # Every section's U comes from one anemometer: across sections they differ only by the projection, i.e. not at all.
    assert_close(res["U"].values[:, 0], res["U"].values[:, 2], rtol=1e-12, atol=1e-12, reason="same wind record")


def test_interpolation_between_two_anemometers(short_event, tmp_path):
    mapping = _write(short_event, tmp_path, rule="interpolation",
                     anemometers={"west": (0, 100.0, ENU, None), "east": (2, 900.0, ENU, None)})
    tree = import_event(mapping)
    a, b = event_arrays(tree), event_arrays(short_event)
    b = {k: np.asarray(b[k], dtype=np.float64) for k in ("u", "v", "acc")}
    # S1 at 250 m: 150/800 of the way from 100 m to 900 m; S2 at 500 m: half way.
    assert_close(a["v"][:, 0], (1 - 0.1875) * b["v"][:, 0] + 0.1875 * b["v"][:, 2], rtol=1e-12, atol=1e-12,
                 reason="two multiplications and a sum in float64")
    assert_close(a["v"][:, 1], 0.5 * (b["v"][:, 0] + b["v"][:, 2]), rtol=1e-12, atol=1e-12,
                 reason="two multiplications and a sum in float64")
    assert [tree.attrs[f"wind_distance_m_S{k}"] for k in (1, 2, 3)] == [150.0, 400.0, 150.0]


def test_span_weights_rules():
    w, d = span_weights([500.0], [0.0, 500.0, 1000.0], "interpolation")
    np.testing.assert_array_equal(w, [[1.0, 1.0, 1.0]])
    np.testing.assert_array_equal(d, [500.0, 0.0, 500.0])
    w, d = span_weights([800.0, 200.0], [100.0, 350.0, 900.0], "interpolation")
    assert_close(w, [[0.0, 0.25, 1.0], [1.0, 0.75, 0.0]])
    assert_close(w.sum(axis=0), 1.0)
    w, _ = span_weights([800.0, 200.0], [100.0, 350.0, 900.0], "nearest")
    np.testing.assert_array_equal(w, [[0.0, 0.0, 1.0], [1.0, 1.0, 0.0]])


@pytest.mark.parametrize("edit, file, words", [
    (lambda t: t.replace("position_m = 500.0", "position_m = 1200.0", 1), "mapping.toml",
     "[wind.mid] position_m = 1200 m is outside the span (0 to span_length_m = 1000 m)"),
    (lambda t: t.replace("span_length_m = 1000.0\n", ""), "mapping.toml", "needs span_length_m"),
    (lambda t: t.replace('acc = "acc_S2"\nposition_m = 500.0', 'acc = "acc_S2"'), "mapping.toml",
     "[accel.S2] needs position_m"),
    (lambda t: t.replace("[wind]", 'wind_rule = "cubic"\n[wind]'), "mapping.toml", "wind_rule 'cubic' is not one of"),
    (lambda t: t.replace('u = "u"', 'format = "instrument"\nu = "u"'), "mapping.toml",
     "[wind.mid] needs heading_deg (the instrument's x axis, degrees from north)"),
    (lambda t: t.replace('u = "u"', 'format = "polar"\nu = "u"'), "mapping.toml", "[wind.mid] has format 'polar'; allowed"),
])
def test_bad_positions_are_one_line_naming_the_mapping(short_event, tmp_path, capsys, edit, file, words):
    mapping = _write(short_event, tmp_path, anemometers={"mid": (1, 500.0, ENU, None)})
    mapping.write_text(edit(mapping.read_text()))
    out = tmp_path / "o" / "F.nc"
    assert main(["import", str(mapping), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and file in err and words in err, err
    assert not out.exists()


def test_known_rotations():
    one, zero = np.array([5.0]), np.array([0.0])
    # Instrument with its x axis towards east (heading 90): x is east, y is north.
    e, n, _ = to_east_north_up("instrument", {"u": one, "v": zero, "w": zero}, 90.0)
    assert_close(np.r_[e, n], [5.0, 0.0], atol=1e-12, reason="sin and cos of 90 degrees in float64")
    e, n, _ = to_east_north_up("instrument", {"u": zero, "v": one, "w": zero}, 90.0)
    assert_close(np.r_[e, n], [0.0, 5.0], atol=1e-12, reason="sin and cos of 90 degrees in float64")
    # Heading 0: x north, y west.
    e, n, _ = to_east_north_up("instrument", {"u": zero, "v": one, "w": zero}, 0.0)
    assert_close(np.r_[e, n], [-5.0, 0.0], atol=1e-12, reason="sin and cos of 0 degrees in float64")
    # Wind from the north blows southwards; from the east (90) westwards; from the south-west (225) to the north-east.
    e, n, w = to_east_north_up("speed_direction", {"speed": np.full(3, 10.0), "direction": np.array([0.0, 90.0, 225.0])})
    assert_close(e, [0.0, -10.0, 10 / np.sqrt(2)], atol=1e-12, reason="sin and cos in float64")
    assert_close(n, [-10.0, 0.0, 10 / np.sqrt(2)], atol=1e-12, reason="sin and cos in float64")
    assert np.isnan(w).all()


def test_instrument_frame_and_speed_direction_files_import_to_east_north_up(short_event, tmp_path):
    arr = {k: np.asarray(v, dtype=np.float64) for k, v in event_arrays(short_event).items() if k != "sections"}
    east, north, up = arr["u"][:, 1], arr["v"][:, 1], arr["w"][:, 1]
    h = np.deg2rad(30.0)
    sonic = {"time": arr["wind_time"], "ux": east * np.sin(h) + north * np.cos(h),
             "uy": -east * np.cos(h) + north * np.sin(h), "uz": up}
    cup = {"time": arr["wind_time"], "spd": np.hypot(east, north) * 3.6,  # km/h
           "dir": np.mod(np.rad2deg(np.arctan2(-east, -north)), 360.0)}
    mapping = _write(short_event, tmp_path, anemometers={
        "sonic": (1, 300.0, ['format = "instrument"', "heading_deg = 30.0", 'u = "ux"', 'v = "uy"', 'w = "uz"'], sonic),
        "cup": (1, 700.0, ['format = "speed_direction"', 'units = "km/h"', 'speed = "spd"', 'direction = "dir"'], cup),
    }, positions=(250.0, 400.0, 750.0))
    tree = import_event(mapping)
    a = event_arrays(tree)
    for j in (0, 1, 2):  # S1, S2 nearest the sonic at 300 m, S3 nearest the cup at 700 m
        assert_close(a["u"][:, j], east, rtol=1e-9, atol=1e-9, reason="rotation and back, km/h and back")
        assert_close(a["v"][:, j], north, rtol=1e-9, atol=1e-9, reason="rotation and back, km/h and back")
    assert_close(a["w"][:, 0], up, rtol=1e-12, atol=1e-12, reason="w is not rotated")
    assert np.isnan(a["w"][:, 2]).all()  # a cup anemometer does not measure w
    assert tree.attrs["import_units_speed_cup"] == "km/h" and "import_units_direction_cup" not in tree.attrs
    assert [tree.attrs[f"wind_distance_m_S{k}"] for k in (1, 2, 3)] == [50.0, 100.0, 50.0]


def test_the_complete_example_of_the_docs_parses(tmp_path):
    
    from vivbench.io.fieldimport import load_mapping

    page = (REPO / "docs" / "field_import.md").read_text()
    toml = page.split("### A complete example", 1)[1].split("```toml\n", 1)[1].split("```", 1)[0]
    for name in ("wind/mid_0800.csv", "wind/mid_0900.csv", "wind/tower_0800.csv", "wind/tower_0900.csv",
                 "acc/deck_0800.csv"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("time\n")
    (tmp_path / "mapping.toml").write_text(toml)
    m = load_mapping(tmp_path / "mapping.toml")
    assert m["sections"] == ["S1", "S2", "S3"] and m["positions_m"] == [272.0, 544.0, 900.0]
    assert [(a["name"], a["format"], a["position_m"]) for a in m["anemometers"]] == [
        ("mid", "instrument", 544.0), ("tower", "speed_direction", 1088.0)]
    mid_u = next(c for c in m["channels"] if c.section == "mid" and c.var == "u")
    assert [p.name for p in mid_u.file.paths] == ["mid_0800.csv", "mid_0900.csv"] and mid_u.rate == 20.0
    _, distance = span_weights([544.0, 1088.0], m["positions_m"], m["wind_rule"])
    np.testing.assert_array_equal(distance, [272.0, 0.0, 188.0])


_pos = st.floats(0.0, 2000.0, allow_nan=False)


@settings(max_examples=100, deadline=None)
@given(anem=st.lists(_pos, min_size=1, max_size=5), secs=st.lists(_pos, min_size=1, max_size=6),
       rule=st.sampled_from(["nearest", "interpolation"]))
def test_span_weights_are_a_convex_combination_and_exact_at_an_anemometer(anem, secs, rule):
    w, d = span_weights(anem, secs, rule)
    assert w.shape == (len(anem), len(secs)) and (w >= 0).all()
    assert_close(w.sum(axis=0), 1.0, atol=1e-12, reason="weights 1 - f and f in float64")
    np.testing.assert_array_equal(d, np.min(np.abs(np.subtract.outer(anem, secs)), axis=0))
    # A linear wind profile along the span is reproduced between the outermost anemometers.
    if rule == "interpolation":
        inside = (np.asarray(secs) >= min(anem)) & (np.asarray(secs) <= max(anem))
        assert_close((np.asarray(anem) @ w)[inside], np.asarray(secs)[inside], rtol=1e-9, atol=1e-9,
                     reason="interpolated positions in float64")


@settings(max_examples=100, deadline=None)
@given(e=st.floats(-60, 60), n=st.floats(-60, 60), heading=st.floats(-720, 720))
def test_instrument_and_meteorological_formats_invert(e, n, heading):
    h = np.deg2rad(heading)
    ux, uy = e * np.sin(h) + n * np.cos(h), -e * np.cos(h) + n * np.sin(h)
    got = to_east_north_up("instrument", {"u": np.array([ux]), "v": np.array([uy]), "w": np.zeros(1)}, heading)
    assert_close(np.r_[got[0], got[1]], [e, n], atol=1e-9, reason="rotation and back in float64")
    d = np.rad2deg(np.arctan2(-e, -n))
    got = to_east_north_up("speed_direction", {"speed": np.array([np.hypot(e, n)]), "direction": np.array([d])})
    assert_close(np.r_[got[0], got[1]], [e, n], atol=1e-9, reason="polar and back in float64")


def test_a_campaign_with_one_mid_span_anemometer_imports_identifies_and_pools(small_campaign, tmp_path):
    """Field files of four events, one anemometer at mid-span for three sections: import, identify, pool."""
    from vivbench.analysis.pool import records_from_results
    from vivbench.analysis.selection import wind_error_scale
    from vivbench.io import read_event
    from vivbench.io.campaign_model import REGIMES_NAME, read_campaign_regimes

    events, results = tmp_path / "events", tmp_path / "results"
    events.mkdir()
    for k, path in enumerate(small_campaign.files):
        raw = tmp_path / f"raw{k}"
        raw.mkdir()
        mapping = _write(read_event(path), raw, anemometers={"mid": (1, 500.0, ENU, None)})
        mapping.write_text(mapping.read_text().replace('event_id = "P1"', f'event_id = "F{k + 1}"'))
        assert main(["import", str(mapping), "--out", str(events / f"F{k + 1}.nc")]) == 0
    assert main(["identify", str(events), "--out", str(results), "--window", "30", "--step", "15"]) == 0
    files = sorted(results.glob("*.identify.nc"))
    assert len(files) == 4
    records = records_from_results(files)
    assert all(r.wind_distance.tolist() == [250.0, 0.0, 250.0] for r in records)
    # The wind perturbations of the verdict see the far sections' error though the spread is 0.
    scale = wind_error_scale(records[0], 60.0)
    assert scale[0] > 0.05 and scale[2] > 0.05 and scale[1] < 1e-9
    assert main(["pool", str(results), "--model", "varying", "--bootstrap", "8", "--block", "20",
                 "--perturbations", "1", "--yaw-degree", "0", "--penalty-choice", "cv"]) == 0
    pooled = read_campaign_regimes(results / REGIMES_NAME)
    assert pooled.sizes["event"] == 4 and pooled["regime"].shape[-1] == 3
