"""The scripts of benchmarks/ stay runnable: every suite benchmark and study imports, every study answers --help.

A renamed or moved library name breaks a script that no other test imports (as
``window_order_stats`` did when it moved to ``vivbench.models``); these checks catch it in
seconds without running the workloads (``make bench`` and ``run_study.py`` do that).
"""

from __future__ import annotations

import importlib.util
import inspect
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import REPO, assert_close, assert_not_close

BENCH = REPO / "benchmarks"


@pytest.fixture
def scripts(monkeypatch):
    """run_all and run_study imported as ``make bench`` runs them (benchmarks/ first on the path)."""
    monkeypatch.syspath_prepend(str(BENCH))
    for name in ("run_all", "run_study", "_pages"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    return _load(BENCH / "run_all.py", monkeypatch), _load(BENCH / "run_study.py", monkeypatch)


def _load(path: Path, monkeypatch):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, path.stem, module)  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def test_every_suite_benchmark_imports_and_takes_its_mode_arguments(scripts, monkeypatch):
    run_all, run_study = scripts
    assert {b.name for b in run_all.SUITE}.isdisjoint(run_study.STUDIES)
    for bench in run_all.SUITE:
        main = _load(BENCH / f"bench_{bench.name}.py", monkeypatch).main
        params = inspect.signature(main).parameters
        for mode in (bench.full, bench.quick):
            assert mode is None or set(mode) <= set(params), f"bench_{bench.name}.main does not take {mode}"


def test_every_study_imports_and_answers_help(scripts, capsys):
    _run_all, run_study = scripts
    assert {"campaign_simulation", "greybox_verdict_bounds", "testing_example", "derivative_campaign"} <= set(
        run_study.STUDIES)
    for name in run_study.STUDIES:
        with pytest.raises(SystemExit) as exc:
            run_study.run_study(name, ["--help"])
        assert exc.value.code == 0, name
        assert "usage:" in capsys.readouterr().out, name


def test_varying_settings_factories_build_campaign_methods(scripts, monkeypatch):
    from vivbench.validate import CampaignMethod

    module = _load(BENCH / "varying_settings.py", monkeypatch)
    for name in ("modal_cv", "modal_least", "modal_loeo", "equal_least"):
        assert isinstance(getattr(module, name)(), CampaignMethod), name


def test_study_page_tables(scripts):
    """A study's figures on its page: cases of flat figures as one table, rows as a table, the rest as figures."""
    _run_all, run_study = scripts
    meta = {"python": "3", "machine": "x", "cpus": 2, "date": "d", "wall_s": 1.0, "cpu_s": 1.0,
            "load_average_1min": 0.5}
    page = run_study.study_page("campaign_simulation", {
        "a": {"error": 0.5, "n": 3}, "b": {"error": 0.25, "n": 4}, "total": 7,
        "rows": [{"event": "E001", "nmse": 0.125}, {"event": "E002", "nmse": float("nan")}], "_run": meta}, "cmd")
    assert "| case | error | n |\n|---|---|---|\n| a | 0.5 | 3 |\n| b | 0.25 | 4 |" in page
    assert "| event | nmse |\n|---|---|\n| E001 | 0.125 |\n| E002 | nan |" in page
    assert "| total | 7 |" in page and "Written by `cmd`" in page and "CPU time 1 s" in page


def test_study_page_opens_with_the_findings(scripts):
    """A study's ``findings`` sentences open its page under their own heading, not as a figure."""
    _run_all, run_study = scripts
    meta = {"python": "3", "machine": "x", "cpus": 2, "date": "d", "wall_s": 1.0, "cpu_s": 1.0,
            "load_average_1min": 0.5}
    page = run_study.study_page("pysindy_variants", {"findings": ["binned: error 0.5.", "weak: refused."],
                                                     "total": 7, "_run": meta}, "cmd")
    said, figures = page.split("## Figures")
    assert "## What the figures show\n\n- binned: error 0.5.\n- weak: refused.\n" in said
    assert "| total | 7 |" in figures and "findings" not in figures


def test_pysindy_variants_study_scores_and_gives_refusal_reasons(scripts, tmp_path, monkeypatch):
    """One capped evaluation draw: every method a row; a weak form that cannot fit says why, the others score."""
    from vivbench.models import pysindy_variants

    _run_all, run_study = scripts
    # support 4 H = 400 s: longer than the 300 s event, so the weak form is refused on this draw
    monkeypatch.setattr(pysindy_variants, "weak", lambda: pysindy_variants.PySINDyWeak(H=100.0))
    figures = run_study.run_study("pysindy_variants", [
        "--draws", "30", "--max-events", "1", "--max-duration", "300", "--out", str(tmp_path / "study"),
        "--methods", "binned,vivbench.models.pysindy_variants:weak"])
    assert figures["draws_failed"] == "none" and figures["capped"] is True
    rows = {r["method"]: r for r in figures["per_draw"]}
    assert set(rows) == {"binned", "weak"}
    assert "4 H = 400 s" in rows["weak"]["reason"] and np.isnan(rows["weak"]["rhs_error_true_AU_energy"])
    assert rows["binned"]["reason"] == "" and np.isfinite(rows["binned"]["rhs_error_true_AU_energy"])
    summary = {r["method"]: r for r in figures["methods"]}
    assert summary["weak"]["draws_scored"] == 0 and summary["weak"]["draws_refused"] == 1
    assert summary["binned"]["draws_scored"] == 1 and summary["binned"]["draws_refused"] == 0
    assert any(s.startswith("weak: refused on every draw") and "400 s" in s for s in figures["findings"])
    assert figures["findings"][0].startswith("Draws: evaluation draws 30 (1 campaigns, 1 events, capped")


def test_truth_wind_study_pairs_the_measured_and_the_truths_wind(scripts, tmp_path):
    """One capped draw: both winds' rows side by side; a measured study of other caps is refused."""
    from vivbench.core.errors import InputError

    _run_all, run_study = scripts
    args = ["--split", "development", "--draws", "18", "--max-events", "2", "--max-duration", "10",
            "--methods", "pooled"]
    figures = run_study.run_study("truth_wind", [*args, "--out", str(tmp_path / "own")])
    (row,) = figures["rows"]
    assert row["draw"] == 18 and row["method"] == "pooled" and row["eiv"] == "smooth"
    # this draw's anemometers see 10 % point turbulence that the deck does not feel (29.9 against 1.19 written)
    assert row["dA_error_truth"] < 0.5 * row["dA_error_measured"]
    winds = {s["wind"]: s for s in figures["summary"]}
    assert winds["truth"]["rhs_error_true_AU_energy_median"] == row["dA_error_truth"]
    assert winds["truth"]["draws_lower_on_truth_wind"] == 1
    assert figures["findings"][0] == ("1 development draws (capped: at most 2 events, events at most 10 min), each "
                                      "studied on the measured wind and on the truth's.")
    # the measured study of another run is read when it differs by nothing but the wind
    again = run_study.run_study("truth_wind", [*args, "--out", str(tmp_path / "reuse"),
                                               "--measured", str(tmp_path / "own" / "measured")])
    assert [(r["dA_error_measured"], r["dA_error_truth"]) for r in again["rows"]] == [
        (row["dA_error_measured"], row["dA_error_truth"])]
    with pytest.raises(InputError, match="max_events"):
        run_study.run_study("truth_wind", ["--split", "development", "--draws", "18", "--max-events", "1",
                                           "--max-duration", "10", "--methods", "pooled",
                                           "--out", str(tmp_path / "other"),
                                           "--measured", str(tmp_path / "own" / "measured")])


def test_segments_study_summarises_the_located_draws_and_the_oracle(scripts, monkeypatch):
    """The segments study's spread and findings: located draws against the model of every event, every draw
    with a step for the oracle split."""
    segments = _load(BENCH / "study_segments.py", monkeypatch)
    nan = float("nan")
    base = {"step_index": 5, "whole_flagged": 0, "whole_flagged_right_share": nan}
    rows = [{**base, "draw": 1, "located_index": 5, "whole_error_all": 0.4, "located_error_all": 0.1,
             "located_error_after": 0.12, "located_whole_error_after": 0.3, "located_flagged": 30,
             "located_flagged_right_share": 0.9, "true_error_all": 0.1, "true_error_after": 0.12,
             "true_whole_error_after": 0.3},
            {**base, "draw": 2, "located_index": -1, "whole_error_all": 0.6, "located_error_all": nan,
             "located_error_after": nan, "located_whole_error_after": nan, "located_flagged": nan,
             "located_flagged_right_share": nan, "true_error_all": 0.2, "true_error_after": 0.25,
             "true_whole_error_after": 0.7}]
    summary = {(s["model"], s["draws"]): s for s in segments.summarise(rows)}
    assert summary[("every event", "located")]["n"] == 1 and summary[("every event", "located")]["median"] == 0.4
    assert summary[("two pieces at the located change", "located")]["after_median"] == 0.12
    assert summary[("every event", "all with a step")]["worst"] == 0.6
    oracle = summary[("two pieces at the true step (oracle)", "all with a step")]
    assert oracle["n"] == 2
    assert_close(oracle["after_median"], 0.185, what="median of 0.12 and 0.25")
    text = segments.findings(rows, segments.summarise(rows))
    assert text[0].startswith("2 draws with a step") and "located a change on 1 (1 within one event" in text[0]
    assert "lower on 1 of 1" in text[1] and "kept on 0" in text[2]


def test_model_derivative_study_compares_the_two_derivatives_draw_by_draw(scripts, monkeypatch):
    """The model_derivative study's summary: spread per method and derivative, the draws where each is lower,
    the promise on draws with enough flags and the change scan's alarms split by the true step."""
    study = _load(BENCH / "study_model_derivative.py", monkeypatch)
    nan = float("nan")

    def row(draw, step, ident, camp, flags=(0, 0), right=(nan, nan), events=("", "")):
        out = {"draw": draw, "step_event": step}
        for deriv, err, f, r, e in zip(study.DERIVATIVES, (ident, camp), flags, right, events):
            out.update({f"varying_{deriv}_error": err, f"varying_{deriv}_curve_error": err / 2,
                        f"varying_{deriv}_flags": f, f"varying_{deriv}_right": r,
                        f"varying_{deriv}_change_p": 0.5, f"varying_{deriv}_change_event": e,
                        f"binned_{deriv}_error": 2 * err, f"binned_{deriv}_curve_error": nan,
                        f"binned_{deriv}_flags": 0, f"binned_{deriv}_right": nan})
        return out

    rows = [row(0, 0, 0.4, 0.3, flags=(30, 25), right=(0.9, 0.96)),
            row(1, 4, 0.2, 0.25, events=("", "E004")),
            row(2, 0, 0.5, nan, events=("E002", ""))]
    summary = {(s["method"], s["derivative"]): s for s in study.summarise(rows)}
    ident, camp = summary[("varying", "identification")], summary[("varying", "campaign")]
    assert_close(ident["error_median"], 0.4, what="median of 0.2, 0.4 and 0.5")
    assert_close(camp["error_median"], 0.275, what="median of 0.25 and 0.3; NaN left out")
    assert (ident["lower_error_draws"], camp["lower_error_draws"], camp["compared_draws"]) == (1, 1, 2)
    assert (ident["promise_kept"], camp["promise_kept"], camp["promise_draws"]) == (0, 1, 1)
    assert (ident["false_alarms"], ident["steps_detected"]) == (1, 0)
    assert (camp["false_alarms"], camp["steps_detected"], camp["draws_with_step"]) == (0, 1, 1)
    assert "false_alarms" not in summary[("binned", "campaign")]
    text = study.findings(study.summarise(rows))
    assert text[1].startswith("varying on the campaign dA/dt") and "alarms on 0 of 2 draws without a step" in text[1]


def test_order_margin_study_counts_the_promise_and_the_forced_only_draws(scripts, monkeypatch):
    """The order_margin study's summary per margin: promise on draws with enough flags, forced-only self-excited
    flags, coverage."""
    study = _load(BENCH / "study_order_margin.py", monkeypatch)

    def row(draw, forced, flags, right, excited):
        out = {"draw": draw, "forced_only": forced}
        for value in study.VALUES:
            k = study._label(value)
            out.update({f"flags_{k}": flags, f"right_{k}": right, f"self_excited_{k}": excited,
                        f"coverage_{k}": flags / 1000})
        return out

    rows = [row(0, False, 100, 99, 10), row(1, True, 300, 100, 200), row(2, False, 10, 0, 0)]
    rows[1]["flags_0.005"], rows[1]["self_excited_0.005"], rows[1]["coverage_0.005"] = 100, 0, 0.1
    summary = {s["order_set_margin"]: s for s in study.summarise(rows)}
    assert (summary["0"]["draws_with_enough_flags"], summary["0"]["promise_kept"]) == (2, 1)
    assert_close(summary["0"]["worst_share_right"], 1 / 3, what="100 of 300 right")
    assert summary["0"]["forced_only_self_excited_flags"] == 200 and summary["0.005"]["forced_only_self_excited_flags"] == 0
    assert (summary["0.005"]["promise_kept"], summary["0.005"]["flags"], summary["0.005"]["flags_right"]) == (2, 210, 199)
    assert_close(summary["0.005"]["coverage_median"], 0.1, what="median of 0.1, 0.1 and 0.01")
    text = study.findings(study.summarise(rows))
    assert text[2].startswith("order_set_margin 0.005: the promise kept on 2 of 2 draws")


def test_wind_smoothing_study_pairs_the_chosen_smoothing_with_the_prior(scripts, monkeypatch):
    """The wind_smoothing study's summary: spread per variant and kind of wind error, the ratio to the stated prior
    draw by draw, the promise and the draws where a smoothing longer or shorter than the prior's was chosen."""
    study = _load(BENCH / "study_wind_smoothing.py", monkeypatch)

    def row(draw, eiv, stated, chosen, label, flags=0, right=0, cv_smoothing=30.0):
        out = {"draw": draw, "eiv": eiv, "forced_only": False}
        for name, err, lab in (("stated", stated, "yaw0-cv"), ("chosen", chosen, label), ("cv", stated, "yaw0-cv")):
            out.update({f"error_{name}": err, f"curve_error_{name}": err / 2, f"flags_{name}": flags,
                        f"right_{name}": right, f"coverage_{name}": flags / 1000, f"self_excited_{name}": 0,
                        f"chosen_{name}": lab, f"fit_s_{name}": 10.0, f"smoothing_{name}": 30.0})
        out["smoothing_cv"] = cv_smoothing  # the cv variant's model records its own smoothing
        return out

    rows = [row(0, "smooth", 0.2, 0.1, "yaw0-cv-smooth90", flags=100, right=99, cv_smoothing=60.0),
            row(1, "smooth", 0.4, 0.6, "yaw0-cv-smooth90", cv_smoothing=10.0),
            row(2, "tributary", 0.3, 0.3, "yaw0-cv-smooth30", flags=50, right=40, cv_smoothing=10.0),
            row(3, "tributary", 0.3, 0.3, "yaw0-cv-smooth15")]
    summary = {(s["variant"], s["draws_of"]): s for s in study.summarise(rows)}
    cv = summary[("cv", "all")]
    assert (cv["longer_smoothing_chosen"], cv["shorter_smoothing_chosen"], cv["shorter_on_tributary"]) == (1, 2, 1)
    assert "shorter_on_tributary" not in summary[("chosen", "all")]
    assert [s["variant"] for s in study.summarise(rows, ("stated", "cv"))] == ["stated", "cv"] * 3
    chosen, stated = summary[("chosen", "all")], summary[("stated", "all")]
    assert_close(chosen["ratio_to_stated_median"], 1.0, what="median of 0.5, 1.5, 1 and 1")
    assert (chosen["better_by_10pct"], chosen["worse_by_10pct"]) == (1, 1)
    assert (chosen["longer_smoothing_chosen"], stated["longer_smoothing_chosen"]) == (2, 0)
    assert chosen["shorter_smoothing_chosen"] == 1  # 15 s is no longer than the prior's 30 s
    assert (chosen["draws_with_enough_flags"], chosen["promise_kept"]) == (2, 1)
    assert_close(summary[("chosen", "smooth")]["error_median"], 0.35, what="median of 0.1 and 0.6")
    assert "ratio_to_stated_median" in summary[("chosen", "tributary")]
    text = study.findings(study.summarise(rows))
    assert text[1].startswith("chosen, all draws (4)")
    assert "a longer smoothing than the prior's chosen on 2, a shorter on 1;" in text[1]
    assert "a shorter on 2 (1 of them where the deck feels the tributary turbulence)" in text[2]


def test_additive_input_study_leaves_out_single_sections_and_counts_the_promise(scripts, monkeypatch):
    """The additive_input study's summary: draws with one section skipped, spread and promise per variant."""
    study = _load(BENCH / "study_additive_input.py", monkeypatch)

    def row(draw, errors, flags, right):
        out = {"draw": draw, "skipped": False}
        for name, err, f, r in zip(study.VARIANTS, errors, flags, right):
            out.update({f"error_{name}": err, f"curve_error_{name}": err, f"flags_{name}": f, f"right_{name}": r,
                        f"coverage_{name}": f / 100, f"fit_s_{name}": 10.0 * (1 + len(name))})
        return out

    rows = [row(0, (0.1, 0.3, 0.2), (50, 0, 40), (50, 0, 30)), row(1, (0.2, 0.5, float("nan")), (0, 0, 0), (0, 0, 0)),
            {"draw": 2, "skipped": True}]
    summary = {s["variant"]: s for s in study.summarise(rows)}
    assert summary["mean"]["draws"] == 2
    assert_close(summary["additive_seed0"]["error_median"], 0.4, what="median of 0.3 and 0.5")
    assert_close(summary["additive"]["error_worst"], 0.2, what="NaN left out")
    assert (summary["additive"]["draws_with_enough_flags"], summary["additive"]["promise_kept"]) == (1, 0)
    assert (summary["mean"]["draws_with_enough_flags"], summary["mean"]["promise_kept"]) == (1, 1)
    assert study.findings(study.summarise(rows))[2].startswith("additive (2 draws with two sections or more)")


def test_family_draw_directory_is_read_only_when_every_event_is_identified(scripts, monkeypatch, tmp_path):
    """A draw directory copied from another study is read; one whose identification stopped part-way is made again."""
    family = _load(BENCH / "_family_args.py", monkeypatch)
    root = tmp_path / "d000"
    assert not family._identified(root)
    (root / "campaign").mkdir(parents=True)
    (root / "identify").mkdir()
    for name in ("E001.nc", "E002.nc", "catalogue.csv"):
        (root / "campaign" / name).write_text("", encoding="utf-8")
    (root / "identify" / "E001.identify.nc").write_text("", encoding="utf-8")
    assert not family._identified(root)
    (root / "identify" / "E002.identify.nc").write_text("", encoding="utf-8")
    assert family._identified(root)
    (root / "campaign" / "catalogue.csv").unlink()
    assert not family._identified(root)


def test_wind_errors_study_extrapolates_and_keeps_the_error_spectrum(scripts, monkeypatch):
    """SIMEX's weights reproduce a polynomial at lambda = -1; a surrogate keeps the amplitude spectrum and mean."""
    study = _load(BENCH / "study_wind_errors.py", monkeypatch)
    lam = (0.0,) + study.LAMBDAS
    f = np.array([[2.0 - 3.0 * x + 0.5 * x**2, 1.0 + x] for x in lam])  # two samples, each a polynomial in lambda
    assert_close(study.extrapolation_weights(lam, 2) @ f, [5.5, 0.0], atol=1e-12, reason="rounding of a zero",
                 what="quadratic at -1, exact")
    assert_close(study.extrapolation_weights(lam, 1) @ f[:, 1], 0.0, atol=1e-12, reason="rounding of a zero",
                 what="line at -1, exact")
    rng = np.random.default_rng(0)
    for n in (300, 301):  # an even length has a Nyquist term, which must stay real
        x = np.cumsum(rng.standard_normal((n, 2)), axis=0)
        y = study.surrogate(x, rng)
        assert y.shape == x.shape
        assert_close(np.abs(np.fft.rfft(y, axis=0)), np.abs(np.fft.rfft(x, axis=0)), atol=1e-9,
                     reason="rounding of the two transforms", what="same amplitude spectrum")
    assert_not_close(y, x, what="a surrogate is not the series")

    def row(draw, eiv, errors, sections=2):
        out = {"draw": draw, "eiv": eiv, "n_sections": sections, "wind_error_actual": 0.4,
               "wind_error_estimated": 0.2 if sections == 1 else 0.5}
        out.update({f"error_{name}": e for name, e in zip(study.VARIANTS, errors)})
        return out

    rows = [row(0, "smooth", (0.4, 0.1, 0.38, 0.5, 0.4, 0.8), sections=1),
            row(1, "tributary", (0.2, 0.2, 0.2, 0.19, 0.2, 0.3))]
    summary = study.summarise(rows)
    by = {(s["variant"], s["draws_of"]): s for s in summary}
    assert_close(by[("truth", "all")]["ratio_to_measured_median"], 0.625, what="median of 0.25 and 1")
    assert (by[("simex_oracle", "all")]["worse_by_10pct"], by[("truth", "smooth")]["better_by_10pct"]) == (2, 1)
    said = study.findings(summary, rows)
    assert said[0].startswith("measured, all draws (2)")
    assert any(s.startswith("The estimated wind error over the actual one, one section (1 draws): median 0.50")
               for s in said)


def test_broken_promise_study_changes_one_thing_per_variant(scripts, monkeypatch):
    """The broken_promise study's variants: another seed, the other felt wind, no buffeting; each row's promise."""
    import dataclasses

    from vivbench.synth.family import draw_bridge

    study = _load(BENCH / "study_broken_promise.py", monkeypatch)
    for index in (18, 109):  # a smooth and a tributary felt wind
        base = draw_bridge("development", index).campaign_config(max_duration=1800.0)
        g = base.generator
        assert study.variant_config(base, "campaign") is base
        for k, name in enumerate(("second_campaign", "third_campaign", "fourth_campaign"), start=1):
            other = study.variant_config(base, name)
            assert other.seed == base.seed + k and other.generator == g
        if g.wind.felt_wind == "tributary":
            with pytest.raises(ValueError, match="already feels the tributary-averaged wind"):
                study.variant_config(base, "tributary_wind")
        else:
            wind = study.variant_config(base, "tributary_wind")
            assert wind.seed == base.seed and dataclasses.replace(wind.generator, wind=g.wind) == g
            assert wind.generator.wind.felt_wind == "tributary"
        calm = study.variant_config(base, "no_buffeting")
        assert (calm.generator.aero.buffeting_w, calm.generator.aero.buffeting_u) == (0.0, 0.0)
        assert dataclasses.replace(calm.generator, aero=g.aero) == g
    with pytest.raises(ValueError, match="unknown variant"):
        study.variant_config(base, "calm")
    row = {"draw": 18, "envelope_time_constant_s": 34.2, "point_timescale_s": 9.3}
    for name, flags, right in zip(study.VARIANTS, (100, 100, 100, 100, 10, 0, 100), (40, 99, 94, 95, 10, 0, 96),
                                  strict=True):
        row.update({f"flags_{name}": flags, f"right_{name}": right, f"error_{name}": 0.2, f"curve_error_{name}": 0.1,
                    f"chosen_{name}": "yaw0-cv"})
    summary = study.summarise([row])
    assert [s["promise"] for s in summary] == ["broken", "kept", "broken", "kept", "untested", "untested", "kept"]
    assert study.findings(summary)[0].startswith("Draw 18 (envelope time constant 34 s, the anemometers' point "
                                                 "turbulence on a time scale of 9 s): campaign 40 of 100 right (broken")
    assert study.findings(summary)[1] == ("Broken, of the campaigns with at least 20 flags: campaign 1 of 1; "
                                          "second_campaign 0 of 1; third_campaign 1 of 1; fourth_campaign 0 of 1; "
                                          "tributary_wind 0 of 0; no_buffeting 0 of 0; truth_wind 0 of 1.")
    row["point_timescale_s"] = None  # a deck that feels the turbulence the anemometers sample
    assert study.findings(study.summarise([row]))[0].startswith("Draw 18 (envelope time constant 34 s): campaign")


def test_broken_promise_study_truth_wind_refits_the_campaign_on_the_truths_wind(scripts, monkeypatch):
    """The variant truth_wind is the draw's own records with the wind the truth's dynamics sees, nothing else."""
    import xarray as xr

    import benchmarks._family_args as family
    from vivbench.core.record import Record
    from vivbench.validate import record_with_truth_wind

    study = _load(BENCH / "study_broken_promise.py", monkeypatch)
    t = np.arange(40) * 0.5
    records = [Record(event_id=f"E00{k}", t=t, A=np.full((t.size, 2), 0.01 * k), U=np.full((t.size, 2), 7.0 + k),
                      dA=np.zeros((t.size, 2))) for k in (1, 2)]
    tt = np.arange(0.0, 25.0, 1.0)
    truths = [xr.Dataset({"U": (("time", "section"), np.column_stack([5.0 + k + 0.1 * tt, 6.0 + k - 0.1 * tt]))},
                         coords={"time": tt}) for k in (1, 2)]
    windows = [(np.array([0.0]), np.array([10.0]))] * 2
    inputs = records, truths, windows
    monkeypatch.setattr(family, "capped_draw", lambda task: inputs)
    got, got_truths, got_windows = study._variant_inputs({"draw": 18}, "truth_wind")
    assert got_truths is truths and got_windows is windows
    for rec, truth, new in zip(records, truths, got, strict=True):
        expected = record_with_truth_wind(rec, truth)
        assert np.array_equal(new.U, expected.U) and np.array_equal(new.A, rec.A)
        assert not np.array_equal(new.U, rec.U)


def test_broken_promise_study_adds_only_the_variants_a_stored_row_lacks(scripts, monkeypatch, tmp_path):
    """A draw scored before a variant was added gains that variant and keeps the others' scores."""
    import json

    import benchmarks._family_args as family

    study = _load(BENCH / "study_broken_promise.py", monkeypatch)
    fitted = []
    monkeypatch.setattr(study, "_variant_inputs", lambda task, name: ([name], [], []))
    monkeypatch.setattr(family, "fit_and_score", lambda method, records, truths, windows: fitted.append(records[0])
                        or {"flags": 30, "right": 30, "error": 0.1, "curve_error": 0.1, "chosen": "yaw0-cv"})
    task = {"split": "development", "draw": 18, "out": str(tmp_path), "max_events": None, "max_duration_s": 1800.0}
    old = {"draw": 18, **{f"{k}_{name}": v for name in ("campaign", "second_campaign", "tributary_wind", "no_buffeting")
                          for k, v in (("flags", 50), ("right", 20), ("error", 0.3), ("curve_error", 0.2),
                                       ("chosen", "yaw0-least"))}}
    family.store_row(task, old)
    row = study.score_draw(task)
    assert fitted == ["third_campaign", "fourth_campaign", "truth_wind"]
    assert row["flags_campaign"] == 50 and row["flags_third_campaign"] == 30 and row["n_events_fourth_campaign"] == 1
    assert json.loads((tmp_path / "d018" / "row.json").read_text()) == row
    assert row["envelope_time_constant_s"] > 0
    assert study.score_draw(task) == row and len(fitted) == 3  # complete: read, not refitted
    tributary = {**task, "draw": 109}  # the deck already feels the tributary average: the variant does not apply
    fresh = study.score_draw(tributary)
    assert "tributary_wind" not in fitted[2:] and fresh["flags_tributary_wind"] == 0
    assert fresh["eiv"] == "tributary" and np.isnan(fresh["error_tributary_wind"])


def test_selection_rule_study_picks_per_rule_and_summarises(scripts, monkeypatch):
    """The selection_rule study: each rule's pick from the same held-out losses (the default's simplest member of
    the confidence set, the lowest total, the set on per-event losses scaled by the event's mean) and the summary
    by whether the yaw matters."""
    study = _load(BENCH / "study_selection_rule.py", monkeypatch)
    complexity = np.array([0, 1, 2])
    # one event dominates the sums: the simple candidate loses it badly and wins the nine others narrowly
    simple = np.array([100.0] + [1.0] * 9)
    rich = np.array([1.0] + [1.1] * 9)
    losses = np.vstack([simple, rich, np.full(10, np.nan)])
    picks = study.rule_choices(losses, complexity, np.array([True, True, False]))
    assert picks == {"simplest": 0, "lowest": 1, "normalised": 0}
    # the rich candidate wins every event by a factor of three: out of every set but its own
    losses = np.vstack([np.full(10, 3.0), np.ones(10), np.full(10, 2.0)])
    picks = study.rule_choices(losses, complexity, np.ones(3, dtype=bool))
    assert picks == {"simplest": 1, "lowest": 1, "normalised": 1}
    assert study._yaw_free_twin(["yaw0-cv", "yaw1-cv"], "yaw1-cv") == "yaw0-cv"
    assert study._yaw_free_twin(["yaw0-cv", "yaw1-cv"], "yaw0-cv") is None

    def row(draw, yaw_range, errors, curves, yaw, free):
        cand = {"yaw0-cv": {"error": errors[0], "curve_error": curves[0]},
                "yaw1-cv": {"error": min(errors) / 2, "curve_error": 0.05}}
        out = {"draw": draw, "yaw_factor_range": yaw_range, "candidates": cand, "simplest_is_default": 1}
        for rule, e, c, y, f in zip(study.RULES, errors, curves, yaw, free):
            out.update({f"error_{rule}": e, f"curve_error_{rule}": c, f"yaw_{rule}": y,
                        f"curve_error_yaw_free_{rule}": f})
        return out

    rows = [row(0, 0.5, (0.4, 0.2, 0.2), (0.3, 0.1, 0.1), (0, 1, 1), (0.3, 0.3, 0.3)),
            row(1, 0.0, (0.2, 0.3, 0.2), (0.2, 0.25, 0.2), (0, 1, 0), (0.2, 0.2, 0.2))]
    summary = {(s["rule"], s["draws_of"]): s for s in study.summarise(rows)}
    assert summary[("lowest", "yaw matters")]["yaw_picked"] == 1
    assert summary[("simplest", "yaw matters")]["yaw_picked"] == 0
    low = summary[("lowest", "yaw does not matter")]
    assert (low["curves_within_10pct_of_yaw_free"], low["curves_compared"]) == (0, 1)
    assert (summary[("lowest", "all")]["better_by_10pct"], summary[("lowest", "all")]["worse_by_10pct"]) == (1, 1)
    assert_close(summary[("normalised", "all")]["ratio_to_simplest_median"], 0.75, what="median of 0.5 and 1")
    oracle = summary[("oracle", "all")]  # the candidate of the lowest error against the truth
    assert_close(oracle["error_median"], 0.1, what="median of 0.1 and 0.1")
    assert oracle["yaw_picked"] == 2
    text = study.findings(study.summarise(rows))
    assert text[0].startswith("simplest, all (2 draws)") and "the selection's own choice on 2 of 2" in text[0]
