"""Output-error refit of coefficients (vivbench.models.refit, vivbench refit)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.signal import savgol_filter

from tests.helpers import assert_close
from vivbench.cli import main
from vivbench.analysis.identify import IdentifyConfig, identify_event
from vivbench.io.result import read_result, result_path
from vivbench.models.refit import RefitConfig, _equation_error_fit, order_rms, refit_coefficients, refit_event, simulate_coefficients
from vivbench.io.event import read_event
from vivbench.io.netcdf import write_netcdf_atomic
from vivbench.core.terms import evaluate_library, feature_names

FS = 2.0  # Hz
DURATION = 300.0  # s
NAMES = feature_names(3)


def _col(section: int, pattern: str) -> int:
    return NAMES.index(pattern.replace("#", str(section + 1)))


def _known_model() -> np.ndarray:
    """Each section's equation uses only its own four terms, so the support is identifiable.

    dA_k/dt = 1e-6 U_k^2 + (0.004 U_k - 0.03) A_k - 0.5 U_k A_k^3: growth for
    U_k > 7.5 m/s, decay below, a cubic limit at a few cm.
    """
    Xi = np.zeros((3, 69))
    for m in range(3):
        Xi[m, _col(m, "U#^2")] = 1e-6
        Xi[m, _col(m, "A# U#")] = 0.004
        Xi[m, _col(m, "A#")] = -0.03
        Xi[m, _col(m, "A#^3 U#")] = -0.5
    return Xi


def _wind(t):
    """Section-dependent wind sweeping 7-9 m/s (so U_k and A_k U_k are not proportional)."""
    t = np.asarray(t, dtype=float)[..., None]
    return 8.0 + np.sin(2 * np.pi * t / 250.0 + np.array([0.0, 1.3, 2.6]))


@pytest.fixture(scope="module")
def clean():
    Xi = _known_model()
    t = np.arange(0.0, DURATION + 1e-9, 1.0 / FS)

    def f(tt, a):
        return (evaluate_library(a[None, :], _wind(np.array([tt]))) @ Xi.T)[0]

    sol = solve_ivp(f, (t[0], t[-1]), [0.01, 0.02, 0.005], t_eval=t, method="DOP853", rtol=1e-12, atol=1e-14)
    assert sol.success, sol.message
    A = sol.y.T
    assert np.ptp(A, axis=0).min() > 0.01 and A.max() > 0.03, "the trajectory must reach the cubic range"
    return {"t": t, "A": A, "U": _wind(t), "Xi": Xi}


def test_recovers_known_coefficients_from_clean_trajectory(clean):
    Xi, support = clean["Xi"], clean["Xi"] != 0
    start = Xi * (1 + 0.1 * np.random.default_rng(0).standard_normal(Xi.shape))  # 10 % off
    fit = refit_coefficients(clean["t"], clean["A"], clean["U"], support, start, RefitConfig())
    assert fit.success, fit.status
    assert np.all(fit.coef[~support] == 0), "coefficients off the support must stay zero"
    # Measured 1.7e-5: the RK4 error at h = 0.5 s against a 1e-12 reference.
    assert_close(fit.coef[support], Xi[support], rtol=1e-4, reason="RK4 on a 0.5 s grid", what="refit coef")
    assert list(fit.rank) == [4, 4, 4] and fit.identifiable
    assert not fit.simulation.stopped and np.all(fit.nmse < 1e-8), fit.nmse


def test_output_error_beats_equation_error_on_noisy_data(clean):
    """1.5 % white noise on A (seed 0), 300 s at 2 Hz, the four-term model per section.

    The equation-error fit is least squares on the same support with a
    Savitzky-Golay derivative (41 samples, cubic) of the noisy A. The refit
    fits the initial state too (``free_initial_state=True``): a noisy first
    sample should not anchor the trajectory. Measured: RMS relative
    coefficient error 0.177 for the refit against 0.250 for the
    equation-error fit. Over seeds 0-7 the refit was better in 7 of 8 cases
    (refit 0.05-0.28, equation error 0.25-1.71; seed 7: 0.277 vs 0.267), so
    this is a typical case, not a guarantee. With the initial state fixed to
    the noisy first sample the refit was better in only 5 of 8 (errors up to
    1.9): the default (fixed) suits scoring from the measured A, not noisy
    coefficient estimation.
    """
    Xi, support = clean["Xi"], clean["Xi"] != 0
    t, A, U = clean["t"], clean["A"], clean["U"]
    rng = np.random.default_rng(0)
    noisy = A + 0.015 * np.sqrt(np.mean(A**2, axis=0)) * rng.standard_normal(A.shape)
    dA = savgol_filter(noisy, 41, 3, deriv=1, delta=1.0 / FS, axis=0)
    lsq = _equation_error_fit(evaluate_library(noisy, U), dA, support)
    fit = refit_coefficients(t, noisy, U, support, lsq, RefitConfig(free_initial_state=True))
    assert fit.success, fit.status

    def err(c):
        return float(np.sqrt(np.mean((c[support] / Xi[support] - 1.0) ** 2)))

    e_refit, e_lsq = err(fit.coef), err(lsq)
    assert e_refit < 0.25, f"refit coefficient error {e_refit:.3f}"
    assert e_lsq > 0.2, f"equation-error coefficient error {e_lsq:.3f}"
    assert e_refit < e_lsq, (e_refit, e_lsq)
    # The trajectory fit is at the noise floor (1.5 % noise -> NMSE ~ 0.0225 * mean(A^2)/var(A)).
    assert np.all(fit.nmse < 0.05), fit.nmse


def test_simulation_and_orders_of_the_true_model(clean):
    sim = simulate_coefficients(clean["t"], clean["A"], clean["U"], clean["Xi"])
    assert not sim.stopped and np.all(sim.nmse < 1e-8), sim.nmse
    orders = order_rms(clean["A"], clean["A"] * 0 + clean["U"], clean["Xi"])
    assert orders.shape == (3, 4) and np.all(orders[:, 2] == 0), "the model has no A^2 term"
    assert np.all(orders[:, [0, 1, 3]] > 0)


def test_config_and_input_validation(clean):
    with pytest.raises(ValueError, match="shooting_interval"):
        RefitConfig(shooting_interval=0.0)
    with pytest.raises(ValueError, match="hessian"):
        RefitConfig(hessian="bfgs")
    with pytest.raises(ValueError, match="substeps"):
        RefitConfig(substeps=0)
    t, A, U, Xi = clean["t"], clean["A"], clean["U"], clean["Xi"]
    with pytest.raises(ValueError, match="support is empty"):
        refit_coefficients(t, A, U, np.zeros((3, 69), dtype=bool), Xi)
    A_bad = A.copy()
    A_bad[5] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        refit_coefficients(t, A_bad, U, Xi != 0, Xi)


@pytest.fixture(scope="module")
def identified(small_campaign_in_library, tmp_path_factory):
    """One event of the small campaign, identified and written; and its event file.

    The in_library campaign: these tests refit on and compare with the truth's exact
    coefficient matrix, which exists only when the truth lies in the library.
    """
    event_file = small_campaign_in_library.files[0]
    tree = read_event(event_file)
    ds = identify_event(tree, IdentifyConfig(), source=str(event_file))
    out = tmp_path_factory.mktemp("refit_result")
    path = write_netcdf_atomic(ds, result_path(out, ds.attrs["event_id"]))
    return {"result": path, "event": event_file, "ds": ds}


def test_refit_event_on_truth_support(identified):
    from vivbench.io.event import event_arrays

    truth = event_arrays(read_event(identified["event"]))["coef"]
    ds = identified["ds"]
    t0 = float(ds["window_start"].values[0])
    mask = _known_model() != 0  # own-section terms only: small and fast
    ev = refit_event(ds, t0=t0, t1=t0 + 40.0, support=mask, truth_coef=truth, config=RefitConfig(max_iter=15))
    assert set(ev.coef) == {"sindy", "lsq", "refit", "truth"}
    assert np.array_equal(ev.support, mask) and ev.support_kind == "mask"
    assert ev.fit.start in ("coef0-trajectory", "coef0", "zero") and ev.fit.iterations >= 1
    assert np.all(ev.coef["refit"][~ev.support] == 0)
    s = ev.summary()
    for name in ("sindy", "lsq", "refit", "truth", "sindy_tv"):
        assert (s[f"nmse_{name}_mean"] is None) == s[f"stopped_{name}"], name
    rows = ev.rows()
    assert rows and all(set(r) >= {"equation", "feature", "sindy", "refit", "truth"} for r in rows)


def test_cli_writes_files_and_rejects_bad_input(identified, tmp_path, capsys):
    out = tmp_path / "refit"
    ds = identified["ds"]
    t0 = float(ds["window_start"].values[0])
    code = main(["refit", str(identified["result"]), "--out", str(out), "--event", str(identified["event"]),
                 "--t0", str(t0), "--t1", str(t0 + 20.0), "--support", "truth", "--max-iter", "5"])
    assert code == 0
    event_id = ds.attrs["event_id"]
    table = (out / f"refit_{event_id}.csv").read_text().splitlines()
    assert table[0].split(",")[:2] == ["equation", "feature"] and len(table) > 1
    summary = json.loads((out / "summary.json").read_text())
    assert {"ipopt_status", "ipopt_iterations", "wall_time_s", "nmse_refit_mean"} <= set(summary)
    from vivbench.io.event import event_arrays

    truth = event_arrays(read_event(identified["event"]))["coef"]
    assert summary["support"] == "truth"
    assert [summary[f"support_size_S{m + 1}"] for m in range(3)] == list((truth != 0).sum(axis=1))
    bad = tmp_path / "bad.identify.nc"
    bad.write_text("not a netcdf file")
    capsys.readouterr()
    assert main(["refit", str(bad), "--out", str(out), "--terms", "A"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("vivbench refit: ") and str(bad) in err and "netcdf" in err.lower() and "\n" not in err, err


def test_cli_refits_an_event_outside_the_library(small_results, tmp_path, capsys):
    """The realistic default has no /truth/coef: the refit runs without the true model; --support truth is refused."""
    camp, _dir, results = small_results
    event = camp.files[0]
    ds = read_result(results[0])
    t0 = float(ds["window_start"].values[0])
    out = tmp_path / "refit"
    capsys.readouterr()
    assert main(["refit", str(results[0]), "--out", str(out), "--event", str(event), "--terms", "U^2, A",
                 "--t0", str(t0), "--t1", str(t0 + 20.0), "--max-iter", "5"]) == 0
    err = capsys.readouterr().err
    assert "no /truth/coef" in err and "no true-model comparison" in err, err
    assert "deprecated" not in err, "a --terms support is not deprecated"
    summary = json.loads((out / "summary.json").read_text())
    assert summary.get("nmse_truth_mean") is None and summary["nmse_refit_mean"] is not None
    assert main(["refit", str(results[0]), "--out", str(out), "--event", str(event), "--support", "truth"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("vivbench refit: ") and "no /truth/coef for --support truth" in err and "\n" not in err, err


def test_cli_identified_support_points_to_greybox(identified, tmp_path, capsys):
    """The refit on an identified support is deprecated (issue 14): it runs, and says to use greybox."""
    ds = identified["ds"]
    t0 = float(ds["window_start"].values[0])
    capsys.readouterr()
    assert main(["refit", str(identified["result"]), "--out", str(tmp_path / "r"), "--t0", str(t0), "--t1",
                 str(t0 + 10.0), "--max-iter", "2", "--support", "identified"]) == 0
    err = capsys.readouterr().err
    assert "deprecated" in err and "vivbench greybox" in err, err
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert summary["solver"] == "gauss-newton" and summary["ipopt_iterations"] <= 2


def test_cli_needs_a_support(identified, tmp_path, capsys):
    """The deprecated identified support is no longer the default: no support is a one-line error, nothing written."""
    capsys.readouterr()
    assert main(["refit", str(identified["result"]), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("vivbench refit: ") and "--terms" in err and "\n" not in err.rstrip("\n"), err
    assert not (tmp_path / "r").exists()
    assert main(["refit", str(identified["result"]), "--out", str(tmp_path / "r"), "--support", "truth",
                 "--terms", "A"]) == 2


def test_own_section_terms_build_the_mask():
    from vivbench.cli.refit import _own_section_mask

    mask = _own_section_mask("U^2, A, A U, A^3 U", NAMES)
    assert mask.sum(axis=1).tolist() == [4, 4, 4]
    assert [NAMES[j] for j in np.flatnonzero(mask[1])] == sorted(["U2^2", "A2", "A2 U2", "A2^3 U2"], key=NAMES.index)
    with pytest.raises(ValueError, match="not a monomial"):
        _own_section_mask("A^4", NAMES)
    with pytest.raises(ValueError, match="comma-separated"):
        _own_section_mask(" , ", NAMES)
