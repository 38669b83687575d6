"""The files of the pysindy models and of the binned baseline (vivbench.io.pysindy_model, vivbench.io.binned_model).

The conformance suite (tests/models/test_conformance.py) checks every built-in model's round trip on its
default settings; here: a user's own ``sindy`` kept in the file, the refusals (what cannot be saved, files of
another model or version, a file whose terms its library does not give), and a pysindy model through
``vivbench pool --model`` and :func:`vivbench.analysis.load_campaign_model`.
"""

from __future__ import annotations

import shutil

import numpy as np
import pysindy as ps
import pytest
import xarray as xr

from vivbench.analysis import load_campaign_model
from vivbench.cli import main
from vivbench.core import InputError
from vivbench.io.model_file import ModelFileError
from vivbench.io.netcdf import NETCDF_ENGINE, write_netcdf_atomic
from vivbench.models import BinnedPolynomial, PySINDyCampaign, PySINDyCP, PySINDyEnsemble, PySINDyWindows


def _user_sindy():
    return ps.SINDy(feature_library=ps.PolynomialLibrary(degree=2, include_bias=False),
                    optimizer=ps.STLSQ(threshold=1e-4, alpha=0.01))


@pytest.fixture(scope="module")
def user_models(bell_campaign):
    return {"campaign": PySINDyCampaign(sindy=_user_sindy()).fit(bell_campaign),
            "windows": PySINDyWindows(sindy=_user_sindy(), window=100.0, step=50.0).fit(bell_campaign)}


@pytest.mark.parametrize("kind", ["campaign", "windows"])
def test_a_users_sindy_is_rebuilt_from_the_file(kind, user_models, bell_campaign, tmp_path):
    model = user_models[kind]
    back = type(model).load(model.save(tmp_path / f"{kind}.nc"))
    assert back.feature_names_ == model.feature_names_ and "1" not in back.feature_names_  # degree 2, no bias
    assert back.sindy.feature_library.get_params() == model.sindy.feature_library.get_params()
    assert back.sindy.optimizer.get_params() == model.sindy.optimizer.get_params()
    for rec in bell_campaign[:2]:
        np.testing.assert_array_equal(back.predict(rec), model.predict(rec))
    # the loaded model refits as the saved one was fitted: its sindy is the same SINDy
    refit = type(model)(**back.get_params()).fit(bell_campaign)
    np.testing.assert_array_equal(refit.coef_, model.coef_)


def test_a_sindy_that_a_file_cannot_rebuild_is_refused(bell_campaign, tmp_path):
    lib = ps.CustomLibrary(library_functions=[lambda x: x, lambda x: x**3],
                           function_names=[lambda x: x, lambda x: f"{x}^3"])
    model = PySINDyCampaign(sindy=ps.SINDy(feature_library=lib)).fit(bell_campaign)
    with pytest.raises(ValueError, match=r"cannot save this model: its sindy's feature_library \(CustomLibrary\)"):
        model.save(tmp_path / "custom.nc")
    assert not list(tmp_path.iterdir()), "a refused save left a file"


def test_files_of_another_model_or_version_are_refused_in_one_line(bell_campaign, tmp_path):
    campaign = PySINDyCampaign().fit(bell_campaign).save(tmp_path / "campaign.nc")
    binned = BinnedPolynomial().fit(bell_campaign).save(tmp_path / "binned.nc")
    cases = [(PySINDyCP.load, campaign, "a PySINDyCampaign file, not a PySINDyCP one"),
             (PySINDyCampaign.load, binned, "not a pysindy model file"),
             (BinnedPolynomial.load, campaign, "not a binned model file"),
             (BinnedPolynomial.load, tmp_path / "missing.nc", "no such binned model file")]
    for path, edit in ((tmp_path / "newer.nc", lambda ds: ds.assign_attrs(format_version=2)),):
        with xr.open_dataset(campaign, engine=NETCDF_ENGINE) as ds:
            write_netcdf_atomic(edit(ds.load()), path)
        cases.append((PySINDyCampaign.load, path, "format_version 2 is not supported"))
    for load, path, fragment in cases:
        with pytest.raises(InputError) as info:
            load(path)
        msg = str(info.value)
        assert msg.startswith(f"{path}: ") and fragment in msg and "\n" not in msg, msg


def test_a_file_whose_terms_its_library_does_not_give_is_refused(bell_campaign, tmp_path):
    path = PySINDyEnsemble(n_models=3).fit(bell_campaign).save(tmp_path / "ensemble.nc")
    with xr.open_dataset(path, engine=NETCDF_ENGINE) as ds:
        ds = ds.load()
    # settings of a degree-2 library beside the 35 terms and coefficients of the degree-3 fit
    ds.attrs["params_json"] = ds.attrs["params_json"].replace('"degree": 3', '"degree": 2')
    write_netcdf_atomic(ds, tmp_path / "edited.nc")
    with pytest.raises(ModelFileError, match="the library rebuilt from the file's settings has the terms"):
        PySINDyEnsemble.load(tmp_path / "edited.nc")


def test_pool_saves_a_pysindy_model_that_load_campaign_model_reads_back(small_results, tmp_path):
    """``vivbench pool --model vivbench.models.pysindy_variants:stlsq``: the model file is the fitted model's."""
    from vivbench.analysis import pool_results, records_from_results

    _campaign, results_dir, files = small_results
    results = tmp_path / "results"
    shutil.copytree(results_dir, results)
    assert main(["pool", str(results), "--model", "vivbench.models.pysindy_variants:stlsq"]) == 0
    model = load_campaign_model(results)
    assert isinstance(model, PySINDyCampaign)
    direct = PySINDyCampaign()
    pool_results(files, direct, wind_smoothing_s=0.0)  # what pool fits, in this process
    np.testing.assert_array_equal(model.coef_, direct.coef_)
    rec = records_from_results(files[:1])[0]
    np.testing.assert_array_equal(model.predict(rec), direct.predict(rec))
