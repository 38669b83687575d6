"""``vivbench study``: draws of the generator family generated, identified and scored per method; resumable."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from tests.helpers import assert_close
from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.validate.study import STUDY_COLUMNS, StudyConfig, method_spec, parse_draws, run_study
from vivbench.validate.study_report import PROMISE_MIN_FLAGS, study_markdown, study_summary

CAPS = dict(max_events=2, max_duration=600.0)
CLAIMS = "tests.validate.test_study:claims_self_excitation"


class _ClaimsEverywhere:
    """A fitted model whose only order is a positive linear one (regime 2) and which flags every window."""

    def fit(self, records):
        return self

    def order_contributions(self, record):
        out = np.zeros((*record.A.shape, 4))
        out[:, :, 1] = 0.01 * record.A
        return out

    def identifiable(self, record, window_start, window_end):
        return np.ones((np.size(window_start), record.n_sections), dtype=bool)


def claims_self_excitation():
    """A plug-in method that claims self-excitation on every window (for the flag counts)."""
    return _ClaimsEverywhere()


@pytest.fixture(scope="module")
def tiny_study(tmp_path_factory):
    out = tmp_path_factory.mktemp("study")
    config = StudyConfig(split="development", draws=(0, 1), methods=("varying", "pooled", CLAIMS), **CAPS)
    result = run_study(config, out, workers=1)
    return config, out, result


def _digests(out):
    return {name: (out / name).read_bytes() for name in ("study.csv", "summary.json", "study.md")}


def test_tiny_study_writes_a_row_per_draw_and_method(tiny_study):
    config, out, result = tiny_study
    assert result.computed == (0, 1) and not result.failures
    lines = (out / "study.csv").read_text().splitlines()
    assert lines[0].split(",") == list(STUDY_COLUMNS)
    rows = [dict(zip(STUDY_COLUMNS, line.split(","))) for line in lines[1:]]
    methods = ("varying", "pooled", CLAIMS)
    assert [(r["draw"], r["method"]) for r in rows] == [(d, m) for d in ("0", "1") for m in methods]
    for r in rows:
        assert r["split"] == "development" and r["n_events"] == "2" and r["error"] == ""
        error = float(r["rhs_error_true_AU_energy"])
        # a sanity bound: on two 10-minute events PooledSINDy's polynomial extrapolates wildly on true (A, U)
        # outside its data (errors of tens); the chosen varying model stays within a few times the truth
        assert 0.0 < error < (10.0 if r["method"] == "varying" else math.inf)
    for r in rows:
        if r["method"] == CLAIMS:  # every window flagged, every flag a claim of self-excitation
            n = int(r["n_scored"])
            assert n > 0 and int(r["n_flagged"]) == n and int(r["self_excited_flags"]) >= n
            assert_close(float(r["flagged_right_share"]), float(r["truth_share_regime2"]), rtol=1e-5,
                         reason="the table rounds to 6 significant digits")
        else:
            assert 0 <= int(r["self_excited_flags"]) and 0 <= int(r["n_flagged"]) <= int(r["n_scored"])
        if r["method"] == "varying":  # the candidate chosen from the campaign's evidence, a member of its set
            assert r["chosen"].startswith("yaw") and r["chosen"] in r["confidence_set"].split(";")
            if r["chosen"].startswith("yaw0"):  # its own curves are the yaw-free model's
                assert r["curve_error_energy_yaw_free"] == r["curve_error_energy"]
        else:
            assert r["chosen"] == "" and r["change_index"] == "-1" and r["curve_error_energy_yaw_free"] == "nan"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["capped"] and summary["draws_scored"] == [0, 1]
    block = summary["methods"]["varying"]["all"]
    assert block["n_draws"] == 2 and block["scores"]["rhs_error_true_AU_energy"]["n"] == 2
    energy = [float(r["rhs_error_true_AU_energy"]) for r in rows if r["method"] == "varying"]
    assert_close(block["scores"]["rhs_error_true_AU_energy"]["median"], float(np.median(energy)), rtol=1e-5,
                 reason="the table rounds to 6 significant digits")
    page = (out / "study.md").read_text()
    assert "Capped campaigns: at most 2 events and events at most 10 min long" in page.splitlines()[2]


def test_rerun_resumes_with_the_same_bytes(tiny_study, tmp_path):
    config, out, _ = tiny_study
    before = _digests(out)
    again = run_study(config, out, workers=1)
    assert again.computed == () and again.resumed == (0, 1)
    assert _digests(out) == before
    # a study killed part-way: the journal holds draw 0 and half a line of draw 1
    journal = (out / "study.jsonl").read_bytes().splitlines(keepends=True)
    first = next(line for line in journal if json.loads(line)["task_id"] == 0)
    (tmp_path / "study.jsonl").write_bytes(first + b'{"task_id": 1, "ok": tr')
    (tmp_path / "study_config.json").write_bytes((out / "study_config.json").read_bytes())
    resumed = run_study(config, tmp_path, workers=1)
    assert resumed.resumed == (0,) and resumed.computed == (1,) and resumed.repaired_lines == 1
    assert _digests(tmp_path) == before


def test_another_study_in_the_same_directory_is_refused(tiny_study):
    _config, out, _ = tiny_study
    with pytest.raises(InputError, match="another split, methods"):
        run_study(StudyConfig(split="development", draws=(0,), methods=("varying",), **CAPS), out)


def test_the_yaw_free_counterpart_of_a_yaw_choice_is_fitted_on_every_event_and_scored(monkeypatch):
    from vivbench.analysis.candidates import Candidate
    from vivbench.validate import study

    class Fake:
        def __init__(self, label):
            self.label, self.fitted_on = label, None

        def fit(self, records):
            self.fitted_on = list(records)
            return self

    scored = []
    monkeypatch.setattr(study, "curve_scores", lambda model, records, truths: (
        scored.append((model.label, model.fitted_on, truths)) or (0.1, 0.2, 0.25)))
    candidates = [Candidate(name=f"yaw{d}-{p}", model=Fake(f"{d}{p}"), options={"yaw_degree": d, "penalty_choice": p})
                  for d in (0, 1) for p in ("cv", "least")]
    records, truths = ["r1", "r2"], ["t1", "t2"]

    def fitted(chosen, among=candidates):  # a selection as a method: its evidence names the choice
        return SimpleNamespace(model=SimpleNamespace(candidates=among), evidence=lambda: {"chosen": chosen})

    def error(chosen, own=0.5):
        return study._yaw_free_curve_error(fitted(chosen), records, truths, own)

    assert error("yaw1-least") == 0.25 and scored == [("0least", records, truths)]  # same penalty, no yaw
    assert candidates[1].model.fitted_on is None  # fitted on a copy
    assert error("yaw0-cv") == 0.5 and len(scored) == 1  # the choice takes no yaw: its own curves
    assert math.isnan(study._yaw_free_curve_error(object(), records, truths, 0.5))  # no selection
    only = fitted("yaw1-cv", [candidates[2]])  # no yaw-free candidate of the same penalty
    assert math.isnan(study._yaw_free_curve_error(only, records, truths, 0.5))


def test_parse_draws_and_config_checks():
    assert parse_draws("0-3") == (0, 1, 2, 3) and parse_draws("5, 1-2,2") == (1, 2, 5)
    for bad in ("3-1", "a", "-2", ""):
        with pytest.raises(InputError, match="draws"):
            parse_draws(bad)
    assert method_spec("pooled") == "pooled" and method_spec("varying") == "varying"
    with pytest.raises(InputError, match="not one of"):
        StudyConfig(split="development", draws=(0,), methods=("no-such-method",))
    with pytest.raises(InputError, match="split"):
        StudyConfig(split="test", draws=(0,), methods=("varying",))
    with pytest.raises(InputError, match="max_duration"):
        StudyConfig(split="evaluation", draws=(0,), methods=("varying",), max_duration=10.0)


def _row(draw, method="m", *, n_flagged=0, right=math.nan, energy=0.1, yaw="absent", forced=False, self_exc=0):
    return {"draw": draw, "method": method, "n_flagged": n_flagged, "flagged_right_share": right,
            "rhs_error_true_AU_energy": energy, "yaw_effect": yaw, "forced_only": forced,
            "self_excited_flags": self_exc, "error": ""}


def test_summary_counts_the_promise_and_forced_only_flags():
    rows = [_row(0, n_flagged=PROMISE_MIN_FLAGS, right=0.96, energy=0.1, yaw="gaussian"),
            _row(1, n_flagged=100, right=0.81, energy=0.4),
            _row(2, n_flagged=PROMISE_MIN_FLAGS - 1, right=0.5, energy=0.2),  # too few flags to judge
            _row(3, n_flagged=30, right=1.0, energy=math.nan, forced=True, self_exc=4, yaw="sin2"),
            _row(4, energy=0.3, forced=True)]
    config = {"split": "development", "draws": [0, 1, 2, 3, 4], "methods": ["m"], "max_events": None,
              "max_duration_s": None}
    s = study_summary(config, rows)
    block = s["methods"]["m"]["all"]
    assert block["promise"] == {"draws_with_enough_flags": 3, "draws_kept": 2, "share_kept": 2 / 3,
                                "worst_flagged_right_share": 0.81, "worst_draw": 1}
    assert block["forced_only"] == {"draws": 2, "self_excited_flags": 4, "draws_with_self_excited_flags": 1}
    energy = block["scores"]["rhs_error_true_AU_energy"]
    assert energy["n"] == 4 and energy["worst"] == 0.4 and energy["worst_draw"] == 1
    assert_close(energy["median"], 0.25, rtol=1e-12, reason="float arithmetic")
    assert_close(energy["p90"], np.percentile([0.1, 0.4, 0.2, 0.3], 90), rtol=1e-12, reason="float arithmetic")
    yaw = s["methods"]["m"]["yaw_present"]
    assert yaw["n_draws"] == 2 and yaw["forced_only"]["self_excited_flags"] == 4
    assert s["methods"]["m"]["yaw_absent"]["n_draws"] == 3
    assert not s["capped"] and "Capped" not in study_markdown(s)
    json.dumps(s, allow_nan=False)  # strict JSON: missing values are null


def test_cli_study_refuses_unknown_methods(tmp_path, capsys):
    from vivbench.cli import main

    assert main(["study", "--split", "development", "--draws", "0", "--methods", "varying,nope",
                 "--out", str(tmp_path)]) == 2
    assert "nope" in capsys.readouterr().err


def test_summary_counts_wins_choices_and_change_alarms():
    from vivbench.validate.study_report import study_markdown, study_summary

    def row(draw, method, err, **kw):
        base = {"draw": str(draw), "method": method, "rhs_error_true_AU_energy": str(err), "yaw_effect": "absent",
                "change": "none", "step_event": "0", "chosen": "", "change_p_value": "nan",
                "change_detected": "0", "change_index": "-1", "error": ""}
        base.update({k: str(v) for k, v in kw.items()})
        return base

    rows = [row(0, "a", 0.1, chosen="yaw0-cv", change_p_value=0.5, yaw_effect="gaussian", yaw_course="shared",
                yaw_factor_range=0.5, confidence_set="yaw0-cv;yaw1-least"),  # the yaw matters, is not chosen, in the set
            row(0, "b", 0.2),
            row(1, "a", 0.3, chosen="yaw1-least", change_p_value=0.01, change_detected=1, change_index=1,
                yaw_effect="gaussian", yaw_course="per_event", yaw_factor_range=0.19, curve_error_energy=0.3,
                curve_error_energy_yaw_free=0.25),  # chosen where it barely matters, curves worse by 20 %
            row(1, "b", 0.2),
            row(2, "a", 0.1, chosen="yaw0-cv", change="damping_step", step_event=4, change_p_value=0.02,
                change_detected=1, change_index=2, yaw_factor_range=0.0, curve_error_energy=0.1,
                curve_error_energy_yaw_free=0.1),     # first changed event E004: index 3, found at 2
            row(2, "b", "nan"),
            row(3, "a", 0.1, chosen="yaw1-cv", change="damping_step", step_event=2, change_p_value=0.4,
                yaw_factor_range=0.0, curve_error_energy=0.2, curve_error_energy_yaw_free=0.19)]  # within 10 %
    summary = study_summary({"split": "development", "draws": [0, 1, 2, 3], "methods": ["a", "b"]}, rows)
    assert summary["versus"]["a vs b"] == {"draws": 2, "lower": 1, "share_lower": 0.5}
    a = summary["methods"]["a"]
    assert a["yaw_present"]["choices"] == {"draws": 2, "yaw_chosen": 1, "per_event_draws": 1, "per_event_yaw_chosen": 1,
                                           "shared_draws": 1, "shared_yaw_chosen": 0, "matters_draws": 1,
                                           "matters_yaw_chosen": 0, "matters_yaw_in_set": 1, "minor_draws": 1,
                                           "minor_yaw_chosen": 1, "minor_curves_compared": 1, "minor_curves_within": 0}
    assert a["yaw_absent"]["choices"] == {"draws": 2, "yaw_chosen": 1, "per_event_draws": 0, "per_event_yaw_chosen": 0,
                                          "shared_draws": 0, "shared_yaw_chosen": 0, "matters_draws": 0,
                                          "matters_yaw_chosen": 0, "matters_yaw_in_set": 0, "minor_draws": 2,
                                          "minor_yaw_chosen": 1, "minor_curves_compared": 2, "minor_curves_within": 2}
    assert a["all"]["changes"] == {"draws_without_change": 2, "false_alarms": 1, "draws_with_step": 2,
                                   "detected": 1, "located_within_one_event": 1}
    assert summary["methods"]["b"]["all"]["changes"]["draws_without_change"] == 0  # never scanned
    page = study_markdown(summary)
    assert "| a vs b | 2 | 1 | 0.500 |" in page and "## Changes the wind does not carry" in page
    assert "| 1, 1 | 1, 0 | 1, 0, 1 | 1, 1, 0 of 1 |" in page  # per-event, shared, where the yaw matters, and not
    assert "| 0, 0 | 0, 0 | 0, 0, 0 | 2, 1, 2 of 2 |" in page
    assert study_markdown(study_summary({"split": "development", "draws": [1], "methods": ["a"]},
                                        [{**rows[2], "curve_error_energy_yaw_free": "nan"}])).count("| 1, 1, n/a |") == 2


def test_summary_splits_the_draws_by_what_their_own_evidence_let_the_verdict_do():
    from vivbench.validate.study_report import study_markdown, study_summary

    def row(draw, err, shown, stationary):
        return {"draw": str(draw), "method": "a", "rhs_error_true_AU_energy": str(err), "yaw_effect": "absent",
                "change": "none", "dynamics_shown": str(shown), "stationary": str(stationary), "error": ""}

    rows = [row(0, 0.1, 1, 1), row(1, 0.3, 1, 1), row(2, 0.9, 0, 1), row(3, 0.5, 1, 0), row(4, 0.7, 0, "")]
    summary = study_summary({"split": "development", "draws": [0, 1, 2, 3, 4], "methods": ["a"]}, rows)
    block = summary["methods"]["a"]["all"]
    assert block["withheld"]["withheld"] == 2 and block["withheld"]["withheld_for_change"] == 1
    allowed, withheld = block["by_evidence"].values()
    assert allowed["n_draws"] == 2 and withheld["n_draws"] == 3
    assert_close(allowed["energy_error"]["median"], 0.2, rtol=1e-12, reason="float arithmetic")
    assert withheld["energy_error"]["worst"] == 0.9 and withheld["energy_error"]["worst_draw"] == 2
    page = study_markdown(summary)
    assert "## By the campaign's own evidence" in page and "| a | regimes withheld | 3 | 0.700 |" in page


def test_the_yaw_factor_range_is_the_truths_factor_over_the_measured_yaws():
    from types import SimpleNamespace

    from vivbench.synth import config_to_dict
    from vivbench.synth.family import draw_bridge
    from vivbench.validate.greybox import truth_yaw_factor
    from vivbench.validate.study import yaw_factor_range

    def truth(split, draw):
        generator = draw_bridge(split, draw).campaign_config().generator
        return SimpleNamespace(attrs={"config_json": json.dumps({"generator": config_to_dict(generator)})})

    t = np.arange(201.0)
    yaw = np.linspace(-30.0, 30.0, 201)[:, None]
    rec = Record(event_id="E1", t=t, A=np.ones((201, 1)), U=np.full((201, 1), 8.0), yaw=yaw)
    logistic = truth("development", 102)  # Y1 falls off with the yaw
    lo, hi = np.percentile(yaw, [5.0, 95.0])
    want = np.ptp(truth_yaw_factor(logistic, np.linspace(lo, hi, 101)))
    assert want > 0.0
    assert_close(yaw_factor_range([rec], [logistic]), want)
    assert yaw_factor_range([rec], [truth("development", 4)]) == 0.0  # no yaw effect on this bridge
    still = Record(event_id="E1", t=t, A=np.ones((201, 1)), U=np.full((201, 1), 8.0), yaw=np.zeros((201, 1)))
    assert yaw_factor_range([still], [logistic]) == 0.0  # one yaw: the factor does not vary over the campaign
    assert math.isnan(yaw_factor_range([rec], [SimpleNamespace(attrs={})]))  # configuration not readable
