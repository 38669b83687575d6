"""Session-scoped simulated data shared by the tests."""

from __future__ import annotations

import os

os.environ.setdefault("MPLBACKEND", "Agg")
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import pytest  # noqa: E402

from vivbench.synth import CampaignConfig, campaign_specs, generate_campaign, simulate_event  # noqa: E402


@pytest.fixture(scope="session")
def default_campaign_specs():
    """Specs and seeds of the default 31-event campaign (nothing simulated)."""
    return campaign_specs(CampaignConfig())


@pytest.fixture(scope="session")
def event1(default_campaign_specs):
    """The default (realistic) campaign's first event (paper-like event 1), simulated in memory."""
    spec, seed = default_campaign_specs[0]
    return spec, simulate_event(spec, CampaignConfig().generator, seed)


@pytest.fixture(scope="session")
def event1_in_library(default_campaign_specs):
    """The same event with the ``in_library`` generator (docs/concepts.md (no inverse crime)): for exact-recovery tests,
    which need the truth inside the library (an exact coefficient matrix)."""
    from vivbench.synth import GeneratorConfig

    spec, seed = default_campaign_specs[0]
    return spec, simulate_event(spec, GeneratorConfig.in_library(), seed)


@pytest.fixture(scope="session")
def small_campaign(tmp_path_factory):
    """A 4-event campaign of 6-9 min events written to disk (one of each scenario)."""
    out = tmp_path_factory.mktemp("campaign")
    result = generate_campaign(CampaignConfig(n_events=4, seed=11, duration=(360.0, 540.0)), out, workers=1)
    assert not result.failures, result.failures
    return result


@pytest.fixture(scope="session")
def small_results(small_campaign, tmp_path_factory):
    """The first two events of ``small_campaign`` identified with the default settings: (campaign, dir, files)."""
    from vivbench.analysis.identify import identify_files

    out = tmp_path_factory.mktemp("small_identify")
    results, failures = identify_files(small_campaign.files[:2], out, workers=1)
    assert not failures, failures
    return small_campaign, out, results


@pytest.fixture(scope="session")
def small_campaign_in_library(tmp_path_factory):
    """``small_campaign`` with the ``in_library`` generator (docs/concepts.md (no inverse crime)).

    For the tests that score coefficients or supports against the truth's exact
    coefficient matrix (``/truth/coef``), which exists only when the truth lies in the library.
    """
    from vivbench.synth import GeneratorConfig

    out = tmp_path_factory.mktemp("campaign_in_library")
    result = generate_campaign(CampaignConfig(n_events=4, seed=11, duration=(360.0, 540.0),
                                              generator=GeneratorConfig.in_library()), out, workers=1)
    assert not result.failures, result.failures
    return result


@pytest.fixture(scope="session")
def small_results_in_library(small_campaign_in_library, tmp_path_factory):
    """``small_results`` of ``small_campaign_in_library``: (campaign, dir, files); see there."""
    from vivbench.analysis.identify import identify_files

    out = tmp_path_factory.mktemp("small_identify_in_library")
    results, failures = identify_files(small_campaign_in_library.files[:2], out, workers=1)
    assert not failures, failures
    return small_campaign_in_library, out, results


@pytest.fixture(scope="session")
def short_event():
    """A 4 min synthetic event in memory (lock-in pass, seed 3): small input for import and bad-input tests."""
    from vivbench.synth import generate_event

    campaign = CampaignConfig(n_events=1, seed=3, duration=(240.0, 240.0))
    spec, seed = campaign_specs(campaign)[0]
    return generate_event(spec, campaign.generator, seed)


@pytest.fixture(scope="session")
def bell_campaign():
    """Four two-section records (600 s at 1 s, noise 1e-4 m/s) of a lock-in bell a_1(U): a small campaign in memory.

    The records of :func:`tests.helpers.bell_records` (dA/dt = a_1(U) A - 2 A^3 with a_1 a bell
    centred at 10 m/s), for checks every campaign model must pass (tests/models/test_conformance.py).
    """
    import numpy as np

    from tests.helpers import bell_records

    return bell_records(4, seed=7, duration_s=600.0, dt_s=1.0, mode_shape=np.array([1.0, 0.8]),
                        wind_period_s=(400.0, 50.0), amplitude_period_s=250.0, noise_m_s=1e-4)
