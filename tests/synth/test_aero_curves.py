"""Aerodynamic functions of reduced velocity, the yaw factor, the named aero modes and their exact truth."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.helpers import REPO, assert_close
from tests.synth.test_bridge import _envelope_error, _pass_script, _quiet_config
from vivbench.synth import (
    AeroConfig,
    Constant,
    EventSpec,
    GaussianBell,
    GeneratorConfig,
    LogisticStep,
    LorentzianBell,
    Polynomial,
    StructureConfig,
    WindScript,
    YawFactor,
    aero_functions,
    amplitude_coefficients,
    amplitude_polynomials,
    config_from_dict,
    config_to_dict,
    curve_from_data,
    draw_aero,
    exact_coefficients,
    load_config,
    order_contributions,
    simulate_event,
    truth_curves,
)

from vivbench.synth.config import bell_polynomial
S = StructureConfig()
FD = S.frequency * S.depth  # m/s per unit of reduced velocity


def test_curves_evaluate_as_documented():
    g = GaussianBell(peak=20.0, center=7.0, width=1.1, baseline=-4.0)
    assert g(7.0) == 20.0
    assert_close(g(np.array([7.0 + 1.1, 60.0])), [-4.0 + 24.0 * np.exp(-0.5), -4.0], rtol=1e-12)
    lo = LorentzianBell(peak=2.0, center=5.0, width=0.5, baseline=0.0)
    assert_close(lo(np.array([5.0, 5.5, 4.5])), [2.0, 1.0, 1.0], rtol=1e-12)
    st_ = LogisticStep(start=36.0, end=20.0, center=7.0, width=1.5)
    assert_close(st_(np.array([7.0, -1e3, 1e3])), [28.0, 36.0, 20.0], rtol=1e-12)
    c = Constant(value=0.5)
    assert c(np.zeros((4, 3))).shape == (4, 3) and np.all(c(np.zeros(2)) == 0.5)
    # curves of reduced velocity see Ur = U / (f1 D); polynomials see U itself
    U = np.array([[6.0, 8.0], [10.0, 12.0]])
    assert_close(g.at_wind(U, S.frequency, S.depth), g(U / FD), rtol=1e-15)
    p = Polynomial(coefficients=(1.0, 2.0, 3.0))
    assert_close(p.at_wind(U, 99.0, 99.0), 1.0 + 2.0 * U + 3.0 * U**2, rtol=1e-15)
    # yaw factor
    assert_close(YawFactor(shape="cosine", exponent=2.0)(np.array([0.0, 60.0])), [1.0, 0.25], rtol=1e-12)
    assert_close(YawFactor(shape="gaussian", width_deg=20.0)(20.0), np.exp(-0.5), rtol=1e-12)
    F = aero_functions(U, S, AeroConfig.realistic(), np.full(U.shape, 20.0))
    assert_close(F["Y1"], g(U / FD) * np.exp(-0.5), rtol=1e-12)
    assert_close(F["e1"], st_(U / FD), rtol=1e-12)


@pytest.mark.parametrize("make, match", [
    (lambda: GaussianBell(peak=1.0, center=7.0, width=0.0), "GaussianBell width must be positive"),
    (lambda: LorentzianBell(peak=1.0, center=-1.0, width=1.0), "LorentzianBell center must be a positive"),
    (lambda: LogisticStep(start=1.0, end=2.0, center=7.0, width=float("nan")), "LogisticStep width must be a finite"),
    (lambda: Constant(value=float("inf")), "Constant value must be a finite"),
    (lambda: YawFactor(shape="square"), "YawFactor shape must be one of 'cosine', 'gaussian', 'sin2', 'logistic'"),
    (lambda: YawFactor(applies_to=("Y3",)), "YawFactor applies_to must name some of"),
    (lambda: curve_from_data({"kind": "sine"}, "Y1"), r"Y1: kind must be one of \['asymmetric', 'constant'"),
    (lambda: curve_from_data({"kind": "gaussian", "peak": 1.0, "centre": 7.0, "width": 1.0}, "Y1"),
     r"Y1: unknown keys \['centre'\] for kind 'gaussian'"),
    (lambda: curve_from_data({"kind": "gaussian", "peak": 1.0}, "Y1"), "Y1: kind 'gaussian' needs"),
    (lambda: AeroConfig.realistic(C_L=GaussianBell(peak=0.04, center=7.0, width=2.0, baseline=-0.01)),
     "C_L must be >= 0 at every wind speed"),
    (lambda: AeroConfig.from_mode("fancy"), r"aero mode must be one of \['in_library', 'realistic'\]"),
    (lambda: config_from_dict({"aero": {"mode": "fancy"}}), "aero mode must be one of"),
])
def test_validation_messages(make, match):
    with pytest.raises(ValueError, match=match) as info:
        make()
    assert "\n" not in str(info.value)


def test_modes_and_exactness():
    # the default is the realistic mode (docs/concepts.md (no inverse crime)); in_library is the named polynomial set
    assert AeroConfig.realistic() == AeroConfig() == GeneratorConfig().aero
    lib = AeroConfig.in_library()
    assert lib.exact_in_library and lib.yaw is None and AeroConfig.from_mode("in_library") == lib
    assert lib.Y1 == bell_polynomial(20.0, 8.0, 2.5) and lib.C_L == bell_polynomial(0.04, 8.0, 8.0)
    real = AeroConfig.realistic()
    assert not real.exact_in_library and exact_coefficients(S, real) is None
    with pytest.raises(ValueError, match="amplitude_polynomials needs"):
        amplitude_polynomials(S, real)
    # a constant is a polynomial of degree 0: still exact
    assert AeroConfig.in_library(C_L=Constant(value=0.02)).exact_in_library
    # a yaw factor leaves the library even with polynomials
    assert not AeroConfig.in_library(yaw=YawFactor()).exact_in_library
    assert AeroConfig.realistic(yaw=None, Y1=LorentzianBell(peak=20.0, center=7.0, width=0.8)).yaw is None


def test_general_averaging_equals_polynomial_path():
    """The truth from curve values (any shapes) equals the in_library polynomial path for polynomials."""
    rng = np.random.default_rng(0)
    U = rng.uniform(3.0, 14.0, size=(50, 3))
    # the polynomial path needs the in_library mode's polynomials
    poly = amplitude_coefficients(U, S, AeroConfig.in_library())
    # a yaw factor at yaw 0 multiplies by 1 but forces the general path
    general = amplitude_coefficients(U, S, AeroConfig.in_library(yaw=YawFactor()), np.zeros_like(U))
    scale = np.abs(poly).max(axis=0)
    assert_close(general / scale, poly / scale, rtol=1e-12, atol=1e-13,
                 reason="sums of products in a different order; the cubic term cancels near the bell's edges")


def test_config_round_trip_and_toml(tmp_path):
    cfg = GeneratorConfig(aero=AeroConfig.realistic(Y1=LorentzianBell(peak=18.0, center=6.5, width=0.9, baseline=-3.0)))
    d = config_to_dict(cfg)
    assert d["aero"]["Y1"] == {"peak": 18.0, "center": 6.5, "width": 0.9, "baseline": -3.0, "kind": "lorentzian"}
    assert d["aero"]["yaw"]["shape"] == "gaussian"
    assert config_from_dict(d) == cfg
    # the in_library saved form: no kind on polynomials, an explicit null yaw (the default has a yaw factor)
    lib = GeneratorConfig.in_library()
    d0 = config_to_dict(lib)
    assert d0["aero"]["yaw"] is None and d0["aero"]["Y1"] == {"coefficients": list(lib.aero.Y1.coefficients)}
    assert config_from_dict(json.loads(json.dumps(d0))) == lib
    assert config_to_dict(GeneratorConfig())["aero"]["yaw"] == config_to_dict(YawFactor(shape="gaussian", width_deg=20.0))
    toml = tmp_path / "aero.toml"
    toml.write_text(
        '[aero]\nmode = "realistic"\n'
        '[aero.Y1]\nkind = "gaussian"\npeak = 22.0\ncenter = 7.2\nwidth = 1.0\nbaseline = -5.0\n'
        '[aero.e2]\nkind = "constant"\nvalue = 400.0\n'
        '[aero.yaw]\nshape = "cosine"\nexponent = 2.0\n'
    )
    got = load_config(toml).aero
    assert got == AeroConfig.realistic(Y1=GaussianBell(peak=22.0, center=7.2, width=1.0, baseline=-5.0),
                                       e2=Constant(value=400.0), yaw=YawFactor(shape="cosine", exponent=2.0))
    assert config_from_dict(config_to_dict(GeneratorConfig(aero=got))).aero == got
    no_yaw = tmp_path / "noyaw.toml"
    no_yaw.write_text('[aero]\nmode = "realistic"\nyaw = false\n')
    assert load_config(no_yaw).aero == AeroConfig.realistic(yaw=None)


def test_old_polynomial_configs_load_identically(tmp_path):
    coefs = [-184.8, 51.2, -3.2]
    a = config_from_dict({"aero": {"Y1": coefs}})
    b = config_from_dict({"aero": {"Y1": {"coefficients": coefs}}})
    c = config_from_dict({"aero": {"Y1": {"kind": "polynomial", "coefficients": coefs}}})
    assert a == b == c and a.aero.Y1 == Polynomial(coefficients=tuple(coefs))
    assert a.aero == AeroConfig(Y1=Polynomial(coefficients=tuple(coefs)))
    toml = tmp_path / "old.toml"
    toml.write_text("[aero.Y1]\ncoefficients = [-184.8, 51.2, -3.2]\n[aero.C_L]\ncoefficients = [0.01]\n")
    cfg = load_config(toml)
    assert cfg.aero.Y1.coefficients == tuple(coefs) and cfg.aero.C_L == Polynomial(coefficients=(0.01,))
    assert config_from_dict(config_to_dict(cfg)) == cfg


def _realistic_event(aero: AeroConfig, plateau: float, yaw_deg: float, T: float = 1500.0, seed: int = 7,
                     structure: StructureConfig | None = None):
    quiet = _quiet_config()
    cfg = GeneratorConfig(structure=structure or StructureConfig(), wind=quiet.wind,
                          aero=dataclasses.replace(aero, cl_unlocked=0.0, buffeting_w=0.0, buffeting_u=0.0))
    s = _pass_script(T, plateau)
    script = WindScript(times=s.times, speeds=s.speeds, yaw_deg=yaw_deg)
    spec = EventSpec(event_id="T", start_time="2026-01-01T00:00:00Z", kind="test", script=script)
    return cfg, simulate_event(spec, cfg, seed)


@pytest.mark.parametrize("aero, plateau, yaw_deg", [
    (AeroConfig.realistic(yaw=None), 8.5, 0.0),
    (AeroConfig.realistic(), 8.5, 12.0),
    (AeroConfig.realistic(yaw=YawFactor(shape="cosine", exponent=3.0)), 8.0, -20.0),
    (AeroConfig.realistic(Y1=LorentzianBell(peak=20.0, center=7.0, width=0.8, baseline=-3.0),
                          C_L=LorentzianBell(peak=0.04, center=7.0, width=2.0)), 9.5, 8.0),
], ids=["gaussian", "gaussian-yaw", "cosine-yaw", "lorentzian-yaw"])
def test_averaged_model_reproduces_envelope_realistic(aero, plateau, yaw_deg):
    cfg, ev = _realistic_event(aero, plateau, yaw_deg)
    assert ev.coef is None, "non-polynomial truth has no exact coefficient matrix"
    assert ev.Q.max() > 0.02, "the pass should excite the deck"
    err = _envelope_error(ev, cfg.structure.omega)
    assert err < 0.02, f"averaged model misses the simulated envelope by {err:.2%} RMS (limit 2 %)"


def test_yaw_weakens_the_vibration():
    aero = AeroConfig.realistic(yaw=YawFactor(shape="gaussian", width_deg=15.0))
    _, straight = _realistic_event(aero, 8.5, 0.0, T=900.0)
    _, yawed = _realistic_event(aero, 8.5, 25.0, T=900.0)
    assert yawed.Q.max() < 0.8 * straight.Q.max()


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), plateau=st.floats(6.5, 9.5), yaw_deg=st.floats(-15.0, 15.0))
def test_averaged_model_reproduces_envelope_drawn(seed, plateau, yaw_deg):
    aero = draw_aero(np.random.default_rng(seed))
    cfg, ev = _realistic_event(aero, plateau, yaw_deg, T=1200.0)
    err = _envelope_error(ev, cfg.structure.omega)
    assert err < 0.02, f"{aero}: envelope error {err:.2%} RMS (limit 2 %)"


@pytest.mark.parametrize("aero", [AeroConfig.in_library(), AeroConfig.realistic()], ids=["in_library", "realistic"])
def test_truth_curves_agree_with_order_contributions(aero):
    wind = np.linspace(3.0, 13.0, 41)
    curves = truth_curves(S, aero, wind)
    assert curves.dims == ("equation", "order", "wind") and curves.shape == (3, 4, 41)
    assert list(curves["equation"].values) == ["S1", "S2", "S3"]
    phi = np.array(S.mode_shape)
    rng = np.random.default_rng(1)
    for j in (0, 17, 40):  # a constant-wind record at three speeds
        Q = rng.uniform(0.001, 0.4, size=30)
        U = np.full((Q.size, 3), wind[j])
        r = order_contributions(Q, U, S, aero, np.zeros_like(U))  # (n, 4) of dQ/dt
        dA = phi[None, :] * r.sum(axis=1)[:, None]  # (n, S)
        A = Q[:, None] * phi[None, :]
        from_curves = (curves.values[None, :, :, j] * A[:, :, None] ** np.arange(4)).sum(axis=-1)
        assert_close(from_curves, dA, rtol=1e-10, atol=1e-14 * np.abs(dA).max(),
                     reason="phi^(1-i) A^i against phi Q^i: rounding of the powers; orders cancel where dA ~ 0")
        # order by order, too
        by_order = phi[None, :, None] * r[:, None, :]
        assert_close(curves.values[:, :, j] * A[:, :, None] ** np.arange(4), by_order,
                     rtol=1e-12, atol=1e-15 * np.abs(by_order).max(), reason="rounding of the powers of phi")
    # the damping -zeta w1 sits in order 1
    far = truth_curves(S, AeroConfig(Y1=Polynomial(coefficients=(0.0,)), C_L=Polynomial(coefficients=(0.0,))), [8.0])
    assert_close(far.values[:, 1, 0], -S.damping_ratio * S.omega, rtol=1e-12)
    assert np.all(far.values[:, [0, 2, 3], 0] == 0.0)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), kind=st.sampled_from(["realistic", "in_library"]), yaw=st.booleans(),
       freq=st.floats(0.2, 0.6), depth=st.floats(2.5, 5.0))
def test_drawn_shapes_give_finite_truth_and_nonnegative_lift(seed, kind, yaw, freq, depth):
    rng = np.random.default_rng(seed)
    aero = draw_aero(rng, kind=kind, yaw=yaw)
    structure = StructureConfig(frequency=freq, depth=depth)
    U = np.linspace(0.5, 16.0, 200)[:, None] * np.ones(3)
    angle = rng.uniform(-30.0, 30.0, size=U.shape)
    F = aero_functions(U, structure, aero, angle)
    assert np.all(F["C_L"] >= 0), "drawn C_L must stay >= 0"
    for name, v in F.items():
        assert np.all(np.isfinite(v)), name
    p = amplitude_coefficients(U, structure, aero, angle)
    assert np.all(np.isfinite(p)) and np.all(p[:, 0] >= 0)
    assert np.all(np.isfinite(truth_curves(structure, aero, U[:, 0]).values))
    assert aero.exact_in_library == (kind == "in_library")
    assert config_from_dict(config_to_dict(GeneratorConfig(aero=aero))).aero == aero


def test_example_file_is_the_realistic_mode():
    
    path = REPO / "examples" / "aero_realistic.toml"
    assert load_config(path).aero == AeroConfig.realistic()


def test_sweep_scales_a_realistic_y1_bell():
    from vivbench.validate.sweep_parameters import PARAMETERS

    gen = GeneratorConfig(aero=AeroConfig.realistic())
    half = PARAMETERS["y1_peak"].apply(gen, 10.0)
    assert half.aero.Y1 == GaussianBell(peak=10.0, center=7.0, width=1.1, baseline=-2.0)


def test_scaled_bell_scales_peak_and_baseline_and_refuses_other_curves():
    from vivbench.core.errors import InputError
    from vivbench.synth.curves import Constant, GaussianBell, scaled_bell

    bell = GaussianBell(peak=2.0, center=7.0, width=1.0, baseline=-0.5)
    twice = scaled_bell(bell, 2.0)
    Ur = np.linspace(4.0, 10.0, 13)
    assert_close(twice(Ur), 2.0 * bell(Ur), rtol=1e-12, reason="products in another order")
    assert (twice.center, twice.width) == (bell.center, bell.width)
    with pytest.raises(InputError, match="only a bell"):
        scaled_bell(Constant(value=1.0), 2.0)
