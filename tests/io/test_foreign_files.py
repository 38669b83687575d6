"""Event files written by other tools load (issue 13).

A small writer below builds an event file with the netCDF4 library alone, in the layout of
docs/formats.md but with none of vivbench's own attributes: no ``config_json`` (the other tool keeps
its settings under another name), no units on the dimensionless regime, no order coordinate, no
``coef`` nor ``curves``, no long names. The arrays are physically sensible (vivbench.synth
simulates them; nothing of vivbench writes them). Identification must not read ``/truth`` at
all; validation needs only time, U, A, r and regime from it.
"""

from __future__ import annotations

import json

import netCDF4
import numpy as np
import pytest
import xarray as xr

from vivbench.analysis.identify import identify_event
from vivbench.cli import main
from vivbench.io.event import read_event
from vivbench.synth import CampaignConfig, campaign_specs, simulate_event

DURATION = 360.0


def write_foreign_event(path, *, truth: str = "full", seed: int = 3, event_id: str = "OTHER01") -> None:
    """Write an event as another tool would: netCDF4 calls only, docs/formats.md layout, no extras.

    ``truth``: "full" (time, U, A, r, regime), "partial" (time and U only), "none".
    """
    campaign = CampaignConfig(n_events=1, seed=seed, duration=(DURATION, DURATION))
    spec, ss = campaign_specs(campaign)[0]
    ev = simulate_event(spec, campaign.generator, ss)
    phi = np.asarray(campaign.generator.structure.mode_shape)
    sections = [f"S{k + 1}" for k in range(phi.size)]
    with netCDF4.Dataset(path, "w", format="NETCDF4") as nc:
        nc.setncatts({"format": "vivbench-event", "format_version": np.int32(1), "event_id": event_id,
                      "start_time": "2024-03-01T12:00:00Z", "source": "synthetic",
                      "span_azimuth_deg": 30.0, "generator": "othertool 0.3"})

        def group(name, time, variables, units):
            g = nc.createGroup(name)
            g.createDimension("time", time.size)
            g.createDimension("section", len(sections))
            tv = g.createVariable("time", "f8", ("time",))
            tv[:] = time
            tv.units = "s"
            sv = g.createVariable("section", str, ("section",))
            for k, s in enumerate(sections):
                sv[k] = s
            for var, values in variables.items():
                v = g.createVariable(var, values.dtype, ("time", "section") + (("order",) if values.ndim == 3 else ()))
                v[...] = values
                if units.get(var):
                    v.units = units[var]
            return g

        group("wind", ev.wind_time, {"u": ev.u, "v": ev.v, "w": ev.w}, {"u": "m s-1", "v": "m s-1", "w": "m s-1"})
        group("accel", ev.accel_time, {"acc": ev.acc}, {"acc": "m s-2"})
        if truth == "none":
            return
        A = (ev.Q[:, None] * phi[None, :]).astype(np.float64)
        if truth == "full":
            nc.createGroup("truth").createDimension("order", 4)
            variables = {"U": ev.U, "A": A, "r": ev.r, "regime": ev.regime.astype(np.int8)}
        else:
            variables = {"U": ev.U}
        g = group("truth", ev.truth_time, variables, {"U": "m/s", "A": "m", "r": "m/s"})
        g.settings_json = json.dumps({"tool": "othertool", "seed": seed})


@pytest.fixture(scope="module")
def foreign_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("foreign")
    write_foreign_event(d / "OTHER01.nc")
    return d


def test_the_writer_is_foreign(foreign_dir):
    """The file has none of vivbench's own truth attributes (so the test shows what it claims)."""
    tree = xr.open_datatree(foreign_dir / "OTHER01.nc")
    truth = tree["truth"]
    assert "config_json" not in truth.attrs and "units" not in truth["regime"].attrs
    assert "order" not in truth.coords and "coef" not in truth.data_vars and "curves" not in truth.data_vars
    tree.close()


def test_foreign_file_identifies_and_validates(foreign_dir, tmp_path, capsys):
    out = tmp_path / "identify"
    assert main(["identify", str(foreign_dir / "OTHER01.nc"), "--out", str(out), "--workers", "1"]) == 0
    result = xr.open_dataset(out / "OTHER01.identify.nc")
    assert result.sizes["window"] >= 5 and np.isfinite(result["f_mode_hz"].values if "f_mode_hz" in result else
                                                        result.attrs["f_mode_hz"])
    # The chain finds the simulated mode (0.327 Hz) from the acceleration spectrum.
    assert abs(result.attrs["f_mode_hz"] - 0.327) < 0.01, result.attrs["f_mode_hz"]
    result.close()
    capsys.readouterr()
    assert main(["validate", str(foreign_dir), str(out), "--out", str(tmp_path / "validate")]) == 0
    text = capsys.readouterr().out
    assert "validate: 1 events" in text and "support n/a" in text, text
    summary = json.loads((tmp_path / "validate" / "summary.json").read_text())
    assert summary["n_events"] == 1
    # The dA/dt error on the truth's own (A, U) is a real number: the truth was used.
    assert np.isfinite(summary["median_rhs_error_true_AU"]), summary


@pytest.mark.parametrize("truth", ["partial", "none"])
def test_identification_never_reads_the_truth(tmp_path, truth):
    """A partial truth (only U) or none at all does not stop identification; read_event(truth=False) drops it."""
    path = tmp_path / "OTHER01.nc"
    write_foreign_event(path, truth=truth)
    tree = read_event(path, truth=False)
    assert "truth" not in tree.children
    if truth == "partial":
        with pytest.raises(ValueError, match=r"OTHER01.nc: missing variable /truth/A"):
            read_event(path)


def test_identify_event_ignores_an_in_memory_truth(foreign_dir):
    """identify_event on a tree whose /truth is not vivbench's gives the same result as without it."""
    tree = read_event(foreign_dir / "OTHER01.nc")
    odd = tree.copy()
    odd["truth"] = xr.DataTree(xr.Dataset({"Q": ("time", np.zeros(3))}, coords={"time": [0.0, 1.0, 2.0]}))
    bare = tree.copy()
    del bare["truth"]
    from vivbench.analysis.identify import IdentifyConfig

    config = IdentifyConfig(window=50.0, step=50.0)
    a, b = identify_event(odd, config), identify_event(bare, config)
    np.testing.assert_array_equal(a["coef"].values, b["coef"].values)
