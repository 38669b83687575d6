"""vivbench.testing: the public strategies and assertions for users' test suites (issue 13)."""

from __future__ import annotations

import re
import subprocess
import sys
import types

import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vivbench.synth import EventSpec, GeneratorConfig, StructureConfig, WindScript, generate_event
from vivbench.testing import (
    CORRUPTION_KINDS,
    Corruption,
    assert_recovers,
    assert_valid_event,
    event_records,
)
from vivbench.testing import strategies as vst
from tests.helpers import REPO, assert_close

DOC = REPO / "docs" / "testing.md"
_FAST = dict(deadline=None, derandomize=True, database=None, suppress_health_check=[HealthCheck.too_slow])


def doc_code() -> str:
    """The Python code blocks of docs/testing.md, joined: the module a user would save as a test file."""
    blocks = re.findall(r"^```python\n(.*?)^```", DOC.read_text(), flags=re.S | re.M)
    assert blocks, "docs/testing.md has no python code block"
    return "\n".join(blocks)


def test_docs_example_runs():
    """The worked property test of docs/testing.md passes (CI runs it here and, from the wheel, in make test-wheel)."""
    module = types.ModuleType("docs_testing_example")
    exec(compile(doc_code(), str(DOC), "exec"), module.__dict__)  # noqa: S102 - our own documentation
    tests = [name for name in vars(module) if name.startswith("test_")]
    assert len(tests) >= 2, tests
    for name in tests:
        getattr(module, name)()


@pytest.fixture(scope="module")
def one_section_event():
    """A 5 min lock-in pass of a one-section bridge with polynomial aerodynamics (truth in the library's class)."""
    config = GeneratorConfig.in_library(structure=StructureConfig(mode_shape=(1.0,), tributary_lengths=(1650.0,)),
                                        initial_amplitude=0.01)
    script = WindScript(times=(0.0, 60.0, 120.0, 300.0), speeds=(5.0, 5.0, 8.8, 8.8))
    return generate_event(EventSpec(event_id="E001", start_time="2026-01-01T00:00:00Z", kind="pass_high",
                                    script=script), config, 5)


class Exact:
    """Reads the exact dynamics of a one-section in-library truth back by least squares (A^i U^j, 23 terms)."""

    terms = [(i, j) for i in range(4) for j in range(6) if i or j]

    def __init__(self, orders=None, verdict=None):
        self.orders, self.verdict = orders, verdict

    def _features(self, record):
        return np.stack([(record.A / 0.05) ** i * (record.U / 8.0) ** j for i, j in self.terms], axis=-1)

    def fit(self, records):
        X = np.concatenate([self._features(r) for r in records])[:, 0]
        y = np.concatenate([r.dA for r in records])[:, 0]
        ok = np.isfinite(X).all(axis=1) & np.isfinite(y)
        self.coef_ = np.linalg.lstsq(X[ok], y[ok], rcond=None)[0]
        return self

    def order_contributions(self, record):
        terms = self._features(record) * self.coef_
        order = np.array([i for i, _ in self.terms])
        r = np.stack([terms[..., order == i].sum(axis=-1) for i in range(4)], axis=-1)
        if self.orders == "all_cubic":
            # The same dA/dt, all of it claimed by the A^3 terms: every regime becomes 4.
            r = np.concatenate([np.zeros(r.shape[:-1] + (3,)), r.sum(axis=-1, keepdims=True)], axis=-1)
        return r


class WithVerdict(Exact):
    def identifiable(self, record, window_start, window_end):
        return np.full((np.size(window_start), record.n_sections), self.verdict)


class Zero:
    """No dynamics at all."""

    def fit(self, records):
        return self

    def order_contributions(self, record):
        return np.zeros(record.A.shape + (4,))


def test_assert_recovers_passes_an_exact_method(one_section_event):
    truth = one_section_event["truth"]
    assert set(np.unique(truth["regime"].values)) >= {1, 2}, "the fixture should hold more than one regime"
    fitted = assert_recovers(Exact(), one_section_event, rhs_tolerance=1e-6, regime_accuracy=0.9)
    assert fitted.coef_.shape == (23,)


def test_assert_recovers_names_event_and_figures(one_section_event):
    with pytest.raises(AssertionError) as info:
        assert_recovers(Zero(), one_section_event)
    msg = str(info.value)
    assert msg.startswith("Zero does not recover the truth on 1 of 1 event(s) (E001)"), msg
    assert "median dA/dt error 1 over" in msg and "(tolerance 0.1)" in msg, msg
    # A model claiming every window for the wrong order fails on regimes though its dA/dt is exact.
    with pytest.raises(AssertionError, match=r"regime accuracy 0 on \d+ windows .*model's \[0, 0, 0, \d+\]"):
        assert_recovers(Exact(orders="all_cubic"), one_section_event, rhs_tolerance=1e-6)


def test_assert_recovers_scores_only_what_the_verdict_claims(one_section_event):
    """A method that flags no window is not scored on regimes (coverage 0); one that flags all is."""
    assert_recovers(WithVerdict(orders="all_cubic", verdict=False), one_section_event, rhs_tolerance=1e-6)
    with pytest.raises(AssertionError, match=r"flagged identifiable"):
        assert_recovers(WithVerdict(orders="all_cubic", verdict=True), one_section_event, rhs_tolerance=1e-6)
    with pytest.raises(AssertionError, match="has no order_contributions"):
        assert_recovers(types.SimpleNamespace(fit=lambda records: object()), one_section_event)


def test_assert_recovers_on_records(one_section_event):
    """Records alone: dA/dt against each record's dA (no order split, so no regimes)."""
    records = event_records(one_section_event)
    assert records[0].event_id == "E001" and records[0].A.shape == (601, 1)
    assert_recovers(Exact(orders="all_cubic"), records, rhs_tolerance=1e-6)
    with pytest.raises(AssertionError, match="median dA/dt error 1 over"):
        assert_recovers(Zero(), records)


@settings(max_examples=3, **_FAST)
@given(event=vst.events(generator=vst.generators(bridge=vst.bridges(n_sections=2), noise_density=20.0),
                        duration=150.0, kind="brief", event_id="X7"))
def test_events_follow_the_format(event):
    assert_valid_event(event)
    assert event.attrs["event_id"] == "X7" and list(event["wind"]["section"].values) == ["S1", "S2"]
    truth = event["truth"]
    assert_close(truth["time"].values[-1], 150.0)
    assert truth["r"].shape[1:] == (2, 4)
    assert np.all((truth["regime"].values >= 1) & (truth["regime"].values <= 4))


@settings(max_examples=10, **_FAST)
@given(bridge=vst.bridges(frequency=0.25, mass=st.just(3.0e4)), aero=vst.aero_curves(kind="realistic", yaw=False),
       script=vst.wind_scripts(kind="outside", duration=200.0, lock_in=(4.0, 8.0)))
def test_plain_values_and_strategies_mix(bridge, aero, script):
    assert bridge.frequency == 0.25 and bridge.mass == 3.0e4 and 1 <= bridge.n_sections <= 4
    assert_close(sum(bridge.tributary_lengths), bridge.span_length)
    assert aero.yaw is None and aero.polynomials() is None
    assert script.duration == 200.0 and all(s < 4.0 or s > 8.0 for s in script.speeds)


def test_campaigns_are_the_generator_s():
    seen = []

    @settings(max_examples=1, **_FAST)
    @given(vst.campaigns(n_events=2, duration=120.0, seed=4,
                         generator=vst.generators(bridge=vst.bridges(n_sections=1), initial_amplitude=0.002)))
    def check(campaign):
        seen.append(campaign)

    check()
    (campaign,) = seen
    assert [e.attrs["event_id"] for e in campaign] == ["E001", "E002"]
    for event in campaign:
        assert_valid_event(event)


@pytest.fixture(scope="module")
def plain_event():
    config = GeneratorConfig.in_library(structure=StructureConfig(mode_shape=(0.8, 0.9), tributary_lengths=(800.0, 800.0)))
    script = WindScript(times=(0.0, 120.0), speeds=(7.0, 8.0))
    return generate_event(EventSpec(event_id="E002", start_time="2026-01-01T00:00:00Z", kind="brief", script=script),
                          config, 1)


@pytest.mark.parametrize("kind", CORRUPTION_KINDS)
def test_corruptions_break_records_not_the_format(plain_event, kind):
    before = plain_event.copy(deep=True)

    @settings(max_examples=5, **_FAST)
    @given(vst.corruptions(kind=kind))
    def check(corruption):
        bad = corruption(plain_event)
        assert_valid_event(bad)
        xr.testing.assert_identical(bad["truth"].to_dataset(), plain_event["truth"].to_dataset())
        xr.testing.assert_identical(plain_event["accel"].to_dataset(), before["accel"].to_dataset())
        groups = ("wind", "accel") if corruption.group == "both" else (corruption.group,)
        t0, t1 = plain_event["accel"]["time"].values, bad["accel"]["time"].values
        if kind == "dropouts":
            for g in groups:
                var = "u" if g == "wind" else "acc"
                assert np.isnan(bad[g][var].values).any(), corruption
        elif kind in ("spikes", "noise"):
            for g in groups:
                var = "u" if g == "wind" else "acc"
                assert not np.array_equal(bad[g][var].values, plain_event[g][var].values), corruption
        elif kind == "clock_offset":
            assert corruption.group == "accel"
            assert_close(t1, (t0 + corruption.size)[t0 + corruption.size >= 0])
        else:
            assert_close(t1, t0 * (1 + corruption.size * 1e-6))

    check()


def test_corruption_refuses_bad_settings():
    with pytest.raises(ValueError, match="kind must be one of"):
        Corruption(kind="gremlins")
    with pytest.raises(ValueError, match="group must be"):
        Corruption(kind="spikes", group="tower")


def test_missing_hypothesis_names_the_extra():
    code = "import sys; sys.modules['hypothesis'] = None\nimport vivbench.testing"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert run.returncode != 0 and "pip install vivbench[testing]" in run.stderr, run.stderr
