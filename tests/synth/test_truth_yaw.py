"""The yaw the averaged truth sees (/truth/yaw): stored where the aerodynamics depend on it, and used to score."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from tests.helpers import assert_close
from vivbench.core.record import Record
from vivbench.io.event import event_arrays, read_event
from vivbench.io.event_schema import EventFormatError, validate_event
from vivbench.preprocess.yaw import event_yaw
from vivbench.validate.recovery import record_with_truth_wind, truth_record


def test_the_truth_stores_the_yaw_it_sees_as_the_anemometers_measure_its_magnitude(small_campaign):
    for path in small_campaign.files:
        tree = read_event(path)
        ev = event_arrays(tree)
        yaw = ev["truth_yaw"]
        assert yaw.shape == ev["U"].shape and np.all((yaw >= 0.0) & (yaw <= 90.0))  # unsigned, degrees
        measured = event_yaw(ev["wind_time"], ev["u"], ev["v"], float(tree.attrs["span_azimuth_deg"]), ev["truth_time"])
        ok = np.isfinite(measured)
        # the anemometers' low-passed yaw scatters about the truth's with their turbulence (1.4-1.9 degrees rms
        # here, against 3.5-5.6 degrees of yaw)
        assert np.sqrt(np.mean((np.abs(measured[ok]) - yaw[ok]) ** 2)) < 0.5 * np.sqrt(np.mean(yaw**2))


def test_no_yaw_is_stored_where_the_aerodynamics_do_not_depend_on_it(small_campaign_in_library):
    tree = read_event(small_campaign_in_library.files[0])
    assert "yaw" not in tree["truth"].ds.data_vars
    assert "truth_yaw" not in event_arrays(tree)


def test_a_truth_yaw_out_of_range_or_without_degrees_is_refused(short_event):
    truth = short_event["truth"].ds
    assert "yaw" in truth.data_vars and truth["yaw"].attrs["units"] == "degree"
    bad_units = short_event.copy()
    bad_units["truth"] = xr.DataTree(truth.assign(yaw=truth["yaw"].assign_attrs(units="rad")))
    with pytest.raises(EventFormatError, match="/truth/yaw has units 'rad'"):
        validate_event(bad_units, "E.nc")
    too_far = short_event.copy()
    too_far["truth"] = xr.DataTree(truth.assign(yaw=truth["yaw"] + 120.0))
    with pytest.raises(EventFormatError, match="/truth/yaw must hold finite angles within"):
        validate_event(too_far, "E.nc")


def _truth(n_t=16, S=2, with_yaw=True):
    tt = np.arange(n_t) * 2.0
    data = {"U": (("time", "section"), np.full((n_t, S), 8.0)), "A": (("time", "section"), np.full((n_t, S), 0.01)),
            "r": (("time", "section", "order"), np.zeros((n_t, S, 4)))}
    if with_yaw:
        data["yaw"] = (("time", "section"), np.column_stack([3.0 + 0.5 * tt, -4.0 - 0.25 * tt]))
    return xr.Dataset(data, coords={"time": tt})


def test_a_model_is_scored_at_the_truths_yaw_where_it_stores_one():
    truth = _truth()
    measured = np.full((16, 2), 20.0)
    assert_close(truth_record(truth, "E001", measured).yaw, truth["yaw"].values)
    assert_close(truth_record(_truth(with_yaw=False), "E001", measured).yaw, measured)


def test_the_oracle_wind_carries_the_truths_yaw():
    n = 40
    t = np.arange(n) * 0.5
    U = np.full((n, 2), 7.0)
    U[4, 0] = np.nan
    rec = Record(event_id="E001", t=t, A=np.full((n, 2), 0.01), U=U, dA=np.zeros((n, 2)), yaw=np.full((n, 2), 30.0))
    out = record_with_truth_wind(rec, _truth())
    ok = np.isfinite(U[:, 0])
    assert_close(out.yaw[ok, 0], 3.0 + 0.5 * t[ok])  # linear in time: interpolation is exact
    assert_close(out.yaw[:, 1], -4.0 - 0.25 * t)
    assert np.isnan(out.yaw[4, 0])  # no measured wind there: no sample
    assert_close(record_with_truth_wind(rec, _truth(with_yaw=False)).yaw, rec.yaw)
