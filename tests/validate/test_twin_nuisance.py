"""The twin's unmeasurable nuisances (vivbench.validate.twin_nuisance) and its mirrored anemometer layout."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.helpers import assert_close
from vivbench.core.errors import InputError
from vivbench.synth import AeroConfig, YAW_SHAPES, generate_event
from vivbench.synth.wind import anemometer_layout
from vivbench.validate.twin import TwinConfig
from vivbench.validate.twin_mirror import (CampaignMirror, EventMirror, TwinBridge, anemometer_fractions,
                                           mirror_generator, mirror_specs, mirror_structure)
from vivbench.synth import E_MIXES
from vivbench.validate.twin_nuisance import MIN_MEAN_YAW_FACTOR, NuisancePriors, apply_nuisances, draw_nuisances

YAWS = np.linspace(-25.0, 25.0, 41)


def _mirror(**layout) -> CampaignMirror:
    event = EventMirror(event_id="F001", start_time="2020-01-01T00:00:00Z", duration=240.0,
                        times=(0.0, 120.0, 240.0), speeds=(9.0, 10.0, 11.0), yaws=(-8.0, 3.0, 12.0), side=1)
    return CampaignMirror(sections=("S1", "S2", "S3"), wind_rate=32.0, accel_rate=50.0, span_azimuth_deg=30.0,
                          turbulence_intensity=0.093, section_offset=0.015, noise_density=42.0, anemometer_offset=0.0,
                          positions=layout.pop("positions", ()), frequency=0.33, mode_shape=(0.7, 1.0, 0.7),
                          identify_json="{}", events=(event,), **layout)


BRIDGE = TwinBridge(mass=2.77e4, depth=3.5, damping_ratio=0.003, span_length=1600.0)


def test_nuisances_are_reproducible_per_seed():
    priors = NuisancePriors()
    draws = [draw_nuisances(priors, YAWS, np.random.default_rng(seed)).to_dict() for seed in (3, 3, 4)]
    assert draws[0] == draws[1]
    assert draws[0] != draws[2]


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), lo=st.floats(0.5, 100.0), width=st.floats(0.0, 200.0),
       bw=st.tuples(st.floats(0.0, 2.0), st.floats(0.0, 2.0)), share=st.floats(0.0, 1.0))
def test_drawn_nuisances_lie_within_their_priors(seed, lo, width, bw, share):
    priors = NuisancePriors(smooth_share=share, point_timescale_s=(lo, lo + width), buffeting_w=tuple(sorted(bw)),
                            buffeting_u=(0.1, 0.2))
    n = draw_nuisances(priors, YAWS, np.random.default_rng(seed))
    assert n.felt_wind in ("tributary", "smooth")
    if n.felt_wind == "smooth":
        assert lo * (1 - 1e-12) <= n.point_timescale_s <= (lo + width) * (1 + 1e-12)
    else:
        assert n.point_timescale_s is None
    assert priors.buffeting_w[0] <= n.buffeting_w <= priors.buffeting_w[1]
    assert 0.1 <= n.buffeting_u <= 0.2
    assert n.yaw_shape in ("absent", *YAW_SHAPES)
    assert n.e_mix in E_MIXES
    if n.yaw is None:
        assert n.yaw_shape == "absent" and n.yaw_mean_factor == 1.0
    else:
        assert n.yaw.applies_to == ("Y1", "C_L")
        assert_close(n.yaw_mean_factor, float(np.mean(n.yaw(YAWS))), what="the mean factor over the measured yaws")
        assert MIN_MEAN_YAW_FACTOR <= n.yaw_mean_factor <= 1.0


def test_the_default_priors_are_the_family_priors_in_proportion():
    rng = np.random.default_rng(0)
    draws = [draw_nuisances(NuisancePriors(), np.zeros(5), rng) for _ in range(400)]
    smooth = np.mean([d.felt_wind == "smooth" for d in draws])
    absent = np.mean([d.yaw is None for d in draws])
    mixes = {m: np.mean([d.e_mix == m for d in draws]) for m in E_MIXES}
    # binomial spread of 400 draws: sd about 0.025
    assert abs(smooth - 0.5) < 0.1 and abs(absent - 0.4) < 0.1
    assert abs(mixes["both"] - 0.5) < 0.1 and abs(mixes["e1_only"] - 0.25) < 0.1 and abs(mixes["e2_only"] - 0.25) < 0.1
    assert {d.yaw_shape for d in draws} == {"absent", *YAW_SHAPES}
    assert max(d.buffeting_w for d in draws) > 1.0 and max(d.buffeting_u for d in draws) > 0.3


def test_the_models_own_split_when_the_priors_say_so():
    priors = NuisancePriors(e_mix_shares=(1.0, 0.0, 0.0))
    assert {draw_nuisances(priors, YAWS, np.random.default_rng(s)).e_mix for s in range(20)} == {"both"}
    assert draw_nuisances(priors, YAWS, np.random.default_rng(0)).to_dict()["e_mix"] == "both"
    assert priors.to_dict()["e_mix_shares"] == [1.0, 0.0, 0.0]


def test_no_yaw_effect_when_the_priors_leave_it_out():
    priors = NuisancePriors(yaw_effect=False)
    assert all(draw_nuisances(priors, YAWS, np.random.default_rng(s)).yaw is None for s in range(20))


def test_a_yaw_effect_that_would_silence_the_measured_winds_is_redrawn():
    yaws = np.full(10, 60.0)  # far from the span's normal: most drawn shapes leave little there
    for seed in range(30):
        n = draw_nuisances(NuisancePriors(), yaws, np.random.default_rng(seed))
        assert n.yaw is None or float(np.mean(n.yaw(yaws))) >= MIN_MEAN_YAW_FACTOR


def test_applied_nuisances_keep_what_is_measured():
    mirror = _mirror()
    structure = mirror_structure(mirror, BRIDGE)
    base = mirror_generator(mirror, structure, AeroConfig(yaw=None))
    for seed in range(12):
        n = draw_nuisances(NuisancePriors(), [y for e in mirror.events for y in e.yaws], np.random.default_rng(seed))
        g = apply_nuisances(base, n)
        assert g.structure == base.structure and g.sensors == base.sensors
        assert (g.wind.anemometer_rate, g.wind.section_offset, g.wind.turbulence, g.wind.span_azimuth_deg) == (
            base.wind.anemometer_rate, base.wind.section_offset, base.wind.turbulence, base.wind.span_azimuth_deg)
        assert (g.wind.anemometer_span, g.wind.anemometer_offset) == (base.wind.anemometer_span,
                                                                      base.wind.anemometer_offset)
        assert g.wind.felt_wind == n.felt_wind
        if n.felt_wind == "smooth":  # the anemometers' point turbulence has the measured intensity
            assert g.wind.point_intensity == base.wind.turbulence.intensity == 0.093
            assert g.wind.point_timescale == n.point_timescale_s
        assert (g.aero.buffeting_w, g.aero.buffeting_u, g.aero.yaw) == (n.buffeting_w, n.buffeting_u, n.yaw)
        assert (g.aero.e1, g.aero.e2, g.aero.strouhal) == (base.aero.e1, base.aero.e2, base.aero.strouhal)
        # averaged over the measured yaws, Y1 and C_L are those drawn from the campaign model
        for name in ("Y1", "C_L"):
            a, b = getattr(g.aero, name), getattr(base.aero, name)
            assert_close(np.array([a.peak, a.baseline]) * n.yaw_mean_factor, np.array([b.peak, b.baseline]))
            assert (a.center, a.width) == (b.center, b.width)


@pytest.mark.parametrize("kwargs, message", [
    ({"smooth_share": 1.5}, "smooth_share must be a probability in \\[0, 1\\]"),
    ({"smooth_share": True}, "smooth_share"),
    ({"point_timescale_s": (60.0, 5.0)}, "point_timescale_s must be \\(low, high\\) with 0.5 <= low <= high"),
    ({"point_timescale_s": (0.1, 5.0)}, "point_timescale_s"),
    ({"buffeting_w": (0.0,)}, "buffeting_w must be \\(low, high\\)"),
    ({"buffeting_u": (-0.1, 0.4)}, "buffeting_u must be \\(low, high\\) with 0 <= low"),
    ({"buffeting_u": (0.0, float("nan"))}, "buffeting_u"),
    ({"yaw_effect": "yes"}, "yaw_effect must be true or false"),
    ({"e_mix_shares": (0.5, 0.5)}, "e_mix_shares must be 3 probabilities \\(both, e1_only, e2_only\\) summing to 1"),
    ({"e_mix_shares": (0.5, 0.25, 0.3)}, "e_mix_shares must be 3 probabilities"),
    ({"e_mix_shares": (1.5, -0.25, -0.25)}, "e_mix_shares"),
    ({"e_mix_shares": "both"}, "e_mix_shares"),
])
def test_priors_are_validated_with_clear_messages(kwargs, message):
    with pytest.raises(InputError, match=message):
        NuisancePriors(**kwargs)


def test_twin_config_takes_priors_or_none():
    assert TwinConfig().priors == NuisancePriors()
    assert TwinConfig(priors=None).priors is None
    with pytest.raises(InputError, match="priors must be a NuisancePriors or None"):
        TwinConfig(priors={"smooth_share": 0.5})


def test_nuisances_need_finite_measured_yaws():
    with pytest.raises(InputError, match="measured yaws"):
        draw_nuisances(NuisancePriors(), [np.nan], np.random.default_rng(0))


def test_a_recorded_anemometer_layout_is_mirrored():
    # three sections at 400, 800, 1300 m of a 1600 m span; one anemometer at mid-span between S2 and S3,
    # one at the S1 end
    mirror = _mirror(positions=(400.0, 800.0, 1300.0), anemometer_positions=(200.0, 1050.0), span_length=1600.0,
                     wind_rule="interpolation")
    structure = mirror_structure(mirror, BRIDGE)  # twin sections at 400, 800, 1200 m
    frac = anemometer_fractions(mirror, structure)
    assert_close(np.array(frac), np.array([200.0, 1000.0]) / 1600.0)
    generator = mirror_generator(mirror, structure, AeroConfig(yaw=None))
    assert generator.wind.anemometer_span == frac and generator.wind.wind_rule == "interpolation"
    layout = anemometer_layout(structure, generator.wind)
    assert not layout.per_section and layout.positions.size == 2
    # the layout survives the nuisances, and an event of the twin records its sections' distances
    n = dataclasses.replace(draw_nuisances(NuisancePriors(), YAWS, np.random.default_rng(1)), felt_wind="smooth",
                            point_timescale_s=10.0)
    spec = dataclasses.replace(mirror_specs(mirror)[0], script=dataclasses.replace(mirror.events[0].script(),
                                                                                   times=(0.0, 30.0),
                                                                                   speeds=(9.0, 9.0),
                                                                                   yaws=(0.0, 0.0)))
    event = generate_event(spec, apply_nuisances(generator, n), 0)
    assert_close(np.array([event.attrs[f"wind_distance_m_S{k}"] for k in (1, 2, 3)]), np.array([200.0, 200.0, 200.0]))


def test_without_a_recorded_layout_the_twin_has_one_anemometer_per_section():
    mirror = _mirror()
    structure = mirror_structure(mirror, BRIDGE)
    assert anemometer_fractions(mirror, structure) is None
    assert mirror_generator(mirror, structure, AeroConfig(yaw=None)).wind.anemometer_span is None
