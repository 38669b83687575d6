"""Fewer anemometers than sections in the generator (WindConfig.anemometer_span, wind_rule)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tests.helpers import assert_close
from vivbench.core.errors import InputError
from vivbench.io import event_arrays, span_weights
from vivbench.synth import CampaignConfig, GeneratorConfig, StructureConfig, WindConfig, campaign_specs
from vivbench.synth import config_from_dict, config_to_dict, generate_event
from vivbench.synth.wind import anemometer_layout


def _event(wind: WindConfig | None = None, structure: StructureConfig | None = None):
    gen = GeneratorConfig.realistic()
    gen = dataclasses.replace(gen, wind=wind or gen.wind, structure=structure or gen.structure)
    campaign = CampaignConfig(n_events=1, seed=3, duration=(240.0, 240.0), generator=gen)
    spec, seed = campaign_specs(campaign)[0]
    return generate_event(spec, gen, seed)


@pytest.mark.parametrize("kwargs, message", [
    ({"anemometer_span": ()}, "anemometer_span must be None"),
    ({"anemometer_span": (1.2,)}, "anemometer_span must be None"),
    ({"anemometer_span": (0.5, 0.5)}, "distinct"),
    ({"anemometer_span": ("mid",)}, "anemometer_span must be None"),
    ({"anemometer_span": (float("nan"),)}, "anemometer_span must be None"),
    ({"anemometer_span": (0.5,), "felt_wind": "anemometer"}, "felt_wind 'tributary' or 'smooth'"),
    ({"anemometer_span": (0.5,), "anemometer_offset": 8.0}, "anemometer_offset must then be 0"),
    ({"wind_rule": "closest"}, "wind_rule must be one of 'nearest', 'interpolation'"),
])
def test_the_layout_is_validated(kwargs, message):
    with pytest.raises(InputError, match=message):
        WindConfig(**kwargs)


def test_one_anemometer_per_section_saves_and_generates_as_before(short_event):
    wind = WindConfig()
    assert "anemometer_span" not in config_to_dict(wind) and "wind_rule" not in config_to_dict(wind)
    assert not any(k.startswith("wind_distance_m_") for k in short_event.attrs)


def test_mid_span_anemometer_gives_every_section_its_wind_and_records_the_distances():
    wind = WindConfig(anemometer_span=[0.5])
    assert wind.anemometer_span == (0.5,)
    assert config_from_dict({**config_to_dict(GeneratorConfig.realistic()), "wind": config_to_dict(wind)}).wind == wind
    tree = _event(wind)
    arr = event_arrays(tree)
    for j in (0, 2):  # S1 and S3 take the mid-span (S2's position) anemometer's record
        np.testing.assert_array_equal(arr["u"][:, j], arr["u"][:, 1])
    span = StructureConfig().span_length
    assert [tree.attrs[f"wind_distance_m_S{k}"] for k in (1, 2, 3)] == [span / 4, 0.0, span / 4]
    # The deck feels its own section's wind: the truth's U differs between the sections.
    U = tree["truth"]["U"].values
    assert np.std(U[:, 0] - U[:, 2]) > 0.05


def test_four_sections_interpolated_between_two_anemometers_as_field_import_does():
    structure = StructureConfig(mode_shape=(0.6, 1.0, 1.0, 0.6), tributary_lengths=(412.5,) * 4)
    wind = WindConfig(anemometer_span=(0.3, 0.7), wind_rule="interpolation")
    layout = anemometer_layout(structure, wind)
    weights, distance = span_weights(layout.positions, structure.positions, "interpolation")
    np.testing.assert_array_equal(layout.to_sections, weights)
    tree = _event(wind, structure)
    assert_close([tree.attrs[f"wind_distance_m_S{k}"] for k in range(1, 5)], distance, rtol=0, atol=0)
    arr = event_arrays(tree)
    u = np.asarray(arr["u"], dtype=np.float64)
    # S1 and S4 lie beyond the anemometers (nearest); S2 at 0.4 and S3 at 0.6 of the span lie a quarter
    # and three quarters of the way from the one at 0.3 to the one at 0.7.
    assert_close(weights[:, 1], [0.75, 0.25], rtol=1e-12, atol=1e-15, reason="positions as fractions of the span")
    assert_close(u[:, 1], 0.75 * u[:, 0] + 0.25 * u[:, 3], rtol=0, atol=1e-5, reason="float32 event records")
    assert_close(u[:, 2], 0.25 * u[:, 0] + 0.75 * u[:, 3], rtol=0, atol=1e-5, reason="float32 event records")
