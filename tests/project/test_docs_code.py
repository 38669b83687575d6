"""The code of docs/methods.md runs as printed: the minimal plug-in and the verdict hook."""

from __future__ import annotations

import re

import numpy as np
from hypothesis import HealthCheck, given, settings

from vivbench.testing import event_records
from vivbench.testing import strategies as vst
from vivbench.validate import score_method
from tests.helpers import REPO, assert_close

DOC = REPO / "docs" / "methods.md"


def _blocks() -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", DOC.read_text(encoding="utf-8"), flags=re.S | re.M)


def _namespace() -> dict:
    blocks = [b for b in _blocks() if "class Damped" in b or "class DampedWithVerdict" in b]
    assert len(blocks) == 2, "docs/methods.md should show the Damped plug-in and its verdict"
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, str(DOC), "exec"), namespace)  # noqa: S102 - our own documentation
    return namespace


@settings(max_examples=2, deadline=None, derandomize=True, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(event=vst.events(duration=300.0))
def test_plugin_and_verdict_of_the_methods_page(event):
    ns = _namespace()
    (record,) = event_records(event)
    truth = event["truth"].to_dataset()
    plain = score_method(ns["make"](), [record], [truth], simulate=False)
    assert plain["coverage"] == 0.0  # no verdict: every window scored, none flagged
    # Regime 1 everywhere: its accuracy is the share of truly regime-1 windows.
    assert_close(plain["accuracy_all"], plain["truth_share_regime1"])
    fitted = ns["DampedWithVerdict"]().fit([record])
    start = np.arange(record.t[0], record.t[-1] - 50.0, 25.0)
    flags = fitted.identifiable(record, start, start + 50.0)
    assert flags.shape == (start.size, record.A.shape[1]) and flags.dtype == bool
    inside = (record.t >= start[:, None]) & (record.t < start[:, None] + 50.0)
    big = np.array([np.nanmean(record.A[w], axis=0) for w in inside]) > 0.05
    assert not (flags & ~big).any()  # never flags a window of small amplitude
