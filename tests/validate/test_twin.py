"""The synthetic twin of a campaign (vivbench.validate.twin*): mirror, determinism, resumption, bad input."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from tests.helpers import REPO, assert_close
from vivbench.analysis.identify import identify_files
from vivbench.analysis.pool import pool_results
from vivbench.analysis.selection import varying_selection
from vivbench.cli import main
from vivbench.core.errors import InputError
from vivbench.io.campaign_model import MODEL_NAME, write_campaign_regimes
from vivbench.io.event import read_event, write_event
from vivbench.io.result import read_result
from vivbench.report import twin_section
from vivbench.synth import AeroConfig, CampaignConfig, generate_campaign, generate_event
from vivbench.validate.twin import TwinConfig, read_twin, run_twin, twin_promise
from vivbench.validate.twin_nuisance import NuisancePriors
from vivbench.validate.twin_mirror import (TwinBridge, measure_campaign, mirror_generator, mirror_specs,
                                           mirror_structure, read_bridge)

BRIDGE = TwinBridge(mass=2.77e4, depth=3.5, damping_ratio=0.003)


@pytest.fixture(scope="module")
def field(tmp_path_factory):
    """A tiny 'field' campaign (3 events of 5-6 min) identified and pooled as vivbench pool does."""
    root = tmp_path_factory.mktemp("twin_field")
    made = generate_campaign(CampaignConfig(n_events=3, seed=5, duration=(300.0, 360.0)), root / "campaign")
    results, failures = identify_files(made.files, root / "identify")
    assert not failures
    model = varying_selection(n_bootstrap=10, n_perturbations=0)
    write_campaign_regimes(pool_results(sorted(results), model), root / "identify")
    model.save(root / "identify" / MODEL_NAME)
    return root, sorted(made.files), sorted(results)


def test_mirror_reproduces_the_campaign_layout(field, tmp_path):
    root, events, results = field
    mirror = measure_campaign(events, results, knot_step=60.0)  # short events: knots every minute
    structure = mirror_structure(mirror, BRIDGE)
    generator = mirror_generator(mirror, structure, AeroConfig())
    twin_files = []
    for i, spec in enumerate(mirror_specs(mirror)):
        twin_files.append(write_event(generate_event(spec, generator, i), tmp_path / "campaign" / f"{spec.event_id}.nc"))
    twin_results, failures = identify_files(twin_files, tmp_path / "identify")
    assert not failures
    again = measure_campaign(twin_files, sorted(twin_results), knot_step=60.0)
    assert again.sections == mirror.sections
    assert (again.wind_rate, again.accel_rate) == (mirror.wind_rate, mirror.accel_rate)
    assert [e.event_id for e in again.events] == [e.event_id for e in mirror.events]
    for field_path, twin_path in zip(events, twin_files):
        f, t = read_event(field_path, truth=False), read_event(twin_path, truth=False)
        assert f.attrs["start_time"] == t.attrs["start_time"]
        assert f["accel"].ds.sizes["time"] == t["accel"].ds.sizes["time"]
        assert f["wind"].ds.sizes["time"] == t["wind"].ds.sizes["time"]
    for a, b in zip(mirror.events, again.events):
        assert a.duration == b.duration and a.times == b.times
        # the twin's measured mean wind follows the field's: its own turbulence and sections' spread differ
        assert_close(np.array(b.speeds), np.array(a.speeds), rtol=0.1, atol=0.3,
                     reason="a new turbulence realisation moves the smoothed mean wind by a few tenths of m/s")
        assert_close(np.abs(b.yaws)[1:-1], np.abs(a.yaws)[1:-1], atol=4.0,
                     reason="yaw of a new turbulence realisation, degrees; the end knots carry the low-pass "
                            "filter's transients")
        assert a.side == b.side
    assert_close(again.turbulence_intensity, mirror.turbulence_intensity, rtol=0.25,
                 reason="intensity of another realisation over a few 10-minute blocks")
    assert_close(again.noise_density, mirror.noise_density, rtol=0.1, reason="noise floor from a finite spectrum")
    assert_close(np.array(again.mode_shape), np.array(structure.mode_shape), atol=0.02,
                 reason="amplitude ratios of noisy envelopes")
    # the amplitude where the nonlinear damping acts: each section's 99th percentile over the events' samples
    A = np.concatenate([read_result(r, ["A"])["A"].values for r in results], axis=0)
    assert_close(np.array(mirror.amplitude_scale), np.nanpercentile(np.where(A > 0, A, np.nan), 99.0, axis=0))
    assert len(again.amplitude_scale) == len(mirror.sections) and min(again.amplitude_scale) > 0


@pytest.fixture(scope="module")
def one_draw(field, tmp_path_factory):
    """A twin of ``field`` with one draw (not to be written to: tests copy it)."""
    root, _, _ = field
    out = tmp_path_factory.mktemp("twin_one") / "twin"
    result = run_twin(root / "campaign", root / "identify", BRIDGE, out, config=TwinConfig(n_draws=1))
    assert result.computed == (0,) and not result.failures
    return out


def test_twin_is_deterministic_and_resumes(field, one_draw, tmp_path):
    root, _, _ = field
    a, b = tmp_path / "a", tmp_path / "b"
    shutil.copytree(one_draw, a)
    both = run_twin(root / "campaign", root / "identify", BRIDGE, b, config=TwinConfig(n_draws=2), workers=2)
    assert both.computed == (0, 1)
    assert read_twin(a)["draws"][0] == read_twin(b)["draws"][0]  # the same draw whatever the worker count
    resumed = run_twin(root / "campaign", root / "identify", BRIDGE, a, config=TwinConfig(n_draws=2))
    assert resumed.resumed == (0,) and resumed.computed == (1,)
    assert (a / "twin.json").read_bytes() == (b / "twin.json").read_bytes()
    assert (a / "twin.md").read_bytes() == (b / "twin.md").read_bytes()
    summary = read_twin(a)
    assert summary["mirror"]["n_events"] == 3
    for stats in summary["expected"].values():
        if stats["n"] >= 2:
            assert stats["predict_low"] <= stats["median"] <= stats["predict_high"]
            assert stats["low"] <= stats["median"] <= stats["high"]
    assert 0.0 <= summary["expected"]["coverage"]["median"] <= 1.0
    # each draw records the nuisances it drew from the stated priors, and the page shows them
    priors = NuisancePriors()
    assert summary["config"]["priors"] == priors.to_dict()
    assert len({json.dumps(r["nuisances"], sort_keys=True) for r in summary["draws"]}) == 2
    for row in summary["draws"]:
        n = row["nuisances"]
        assert n["felt_wind"] in ("tributary", "smooth")
        assert priors.buffeting_w[0] <= n["buffeting_w"] <= priors.buffeting_w[1]
        assert priors.buffeting_u[0] <= n["buffeting_u"] <= priors.buffeting_u[1]
    assert "| draw | felt wind | point time scale, s |" in (a / "twin.md").read_text()
    section = "\n".join(twin_section(a))
    assert section.startswith("## How far to trust this")
    assert "3 events" in section and "dA/dt error, energy-weighted" in section
    assert "the deck felt a smooth wind in" in section and "of 2 twins" in section
    expected = twin_promise([r["scores"] for r in summary["draws"]])
    assert (summary["promise"]["tested"], summary["promise"]["broken"]) == (expected["tested"], expected["broken"])
    assert_close(summary["promise"]["broken_upper"], expected["broken_upper"], what="NaN when none was tested")
    page = (a / "twin.md").read_text()
    assert ("was tested on" in page) if summary["promise"]["tested"] else ("promise was not tested" in page)


def test_a_journalled_draw_survives_a_failed_run(field, one_draw, tmp_path):
    root, _, _ = field
    out = tmp_path / "t"
    shutil.copytree(one_draw, out)
    journal = (out / "twin.jsonl").read_text()
    with (out / "twin.jsonl").open("a") as fh:
        fh.write('{"task_id": 1, "ok": tr')  # a run killed while writing its next line
    again = run_twin(root / "campaign", root / "identify", BRIDGE, out, config=TwinConfig(n_draws=1))
    assert again.resumed == (0,) and again.computed == ()
    assert (out / "twin.jsonl").read_text() == journal
    assert (out / "twin.json").read_bytes() == (one_draw / "twin.json").read_bytes()
    with pytest.raises(InputError, match="twin of another"):
        run_twin(root / "campaign", root / "identify", BRIDGE, out, config=TwinConfig(n_draws=1, seed=1))


def test_missing_bridge_file_is_one_line_naming_it(field, tmp_path, capsys):
    root, _, _ = field
    missing = tmp_path / "nope.toml"
    code = main(["twin", str(root / "campaign"), str(root / "identify"), "--bridge", str(missing),
                 "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and str(missing) in err[0] and "no such bridge file" in err[0]
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("text, message", [
    ("[bridge]\ndepth = 3.5\ndamping_ratio = 0.003\n", "mass"),
    ("[bridge]\nmass = 2e4\ndepth = 3.5\ndamping_ratio = 0.003\nwidth = 30\n", "unknown bridge key"),
    ("[bridge]\nmass = -2e4\ndepth = 3.5\ndamping_ratio = 0.003\n", "mass"),
])
def test_bad_bridge_file_names_the_file(tmp_path, text, message):
    path = tmp_path / "bridge.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=message) as err:
        read_bridge(path)
    assert str(path) in str(err.value)


def test_bridge_mode_shape_must_match_the_sections(field):
    _, events, results = field
    mirror = measure_campaign(events[:1], results[:1])
    with pytest.raises(InputError, match="mode_shape has 2 values for 3 sections"):
        mirror_structure(mirror, TwinBridge(mass=2e4, depth=3.0, damping_ratio=0.005, mode_shape=(1.0, 0.5)))


@pytest.mark.parametrize("kwargs", [{"n_draws": 0}, {"seed": -1}, {"knot_step": 1.0}, {"max_events": 0}])
def test_twin_config_refuses_bad_values(kwargs):
    with pytest.raises(InputError):
        TwinConfig(**kwargs)


def test_twin_json_is_refused_when_not_a_twin(tmp_path):
    (tmp_path / "twin.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(InputError, match="not a twin summary"):
        read_twin(tmp_path)


@pytest.mark.parametrize("kwargs", [{"split": "test"}, {"draws": (2, 1)}, {"n_twins": 0}, {"bootstrap": 1}])
def test_twin_check_config_refuses_bad_values(kwargs):
    from vivbench.validate import TwinCheckConfig

    with pytest.raises(InputError):
        TwinCheckConfig(**kwargs)


@pytest.mark.slow
def test_twin_check_compares_actual_figures_with_the_twin_range(tmp_path):
    from vivbench.validate import CHECKED_METRICS, TwinCheckConfig, run_twin_check

    config = TwinCheckConfig(split="development", draws=(0,), n_twins=2, max_events=3, max_duration=300.0,
                             bootstrap=10)
    path, page, failures = run_twin_check(config, tmp_path)
    assert not failures
    summary = json.loads(path.read_text())
    (row,) = summary["draws"]
    for m in CHECKED_METRICS:
        lo, hi, a = row["expected"][m]["predict_low"], row["expected"][m]["predict_high"], row["actual"][m]
        if row["inside"][m] is not None:
            assert row["inside"][m] == (lo <= a <= hi)
        assert summary["share_inside"][m]["assessed"] == int(row["inside"][m] is not None)
    assert "Does the twin predict?" in page.read_text()
    assert len(row["twin_nuisances"]) == 2 and all(n["felt_wind"] for n in row["twin_nuisances"])


def test_the_greybox_bridge_example_is_a_twin_bridge_file():
    bridge = read_bridge(REPO / "examples" / "greybox_bridge_default.toml")
    assert (bridge.mass, bridge.depth, bridge.frequency, bridge.mode_shape) == (27700.0, 3.5, 0.327, (0.707, 1.0, 0.707))


def test_fixed_nuisances_keep_the_generator_defaults(field, tmp_path):
    root, _, _ = field
    out = tmp_path / "fixed"
    code = main(["twin", str(root / "campaign"), str(root / "identify"), "--bridge",
                 str(REPO / "examples" / "greybox_bridge_default.toml"), "--out", str(out), "--draws", "1",
                 "--fixed-nuisances", "--workers", "1"])
    assert code == 0
    summary = read_twin(out)
    assert summary["config"]["priors"] is None and summary["draws"][0]["nuisances"] is None
    page = (out / "twin.md").read_text()
    assert "Fixed at the generator's defaults" in page and "| draw | felt wind |" not in page


def test_a_recorded_anemometer_layout_is_measured(field, tmp_path):
    """Events imported with positions (one anemometer at 700 m for three sections) give the mirror their layout."""
    _, events, results = field
    copies = []
    for path in events:
        tree = read_event(path)
        tree.attrs.update({"import_span_length_m": 1650.0, "import_wind_rule": "interpolation",
                           "import_anemometer_position_m_mid": 700.0, "import_position_m_S1": 412.5,
                           "import_position_m_S2": 825.0, "import_position_m_S3": 1237.5,
                           "wind_distance_m_S1": 287.5, "wind_distance_m_S2": 125.0, "wind_distance_m_S3": 537.5})
        copies.append(write_event(tree, tmp_path / path.name))
    mirror = measure_campaign(copies, results)
    assert (mirror.anemometer_positions, mirror.span_length, mirror.wind_rule) == ((700.0,), 1650.0, "interpolation")
    assert mirror.positions == (412.5, 825.0, 1237.5)
    wind = mirror_generator(mirror, mirror_structure(mirror, BRIDGE), AeroConfig()).wind
    assert_close(np.array(wind.anemometer_span), np.array([700.0 / 1650.0]))
    assert wind.wind_rule == "interpolation" and wind.anemometer_offset == 0.0


def test_the_twin_refits_with_the_field_runs_selection_settings(field):
    from vivbench.analysis.held_out import RANK_LEVEL
    from vivbench.analysis.selection import LIMIT_TIME_CONSTANTS, SINGLE_SECTION_SHARE
    from vivbench.validate.twin_chain import pool_method, pool_settings

    root, _, _ = field
    settings = pool_settings(root / "identify")
    assert settings.selection["n_perturbations"] == 0
    assert settings.selection["single_section_share"] == SINGLE_SECTION_SHARE
    assert settings.selection["min_time_constants"] == LIMIT_TIME_CONSTANTS
    assert settings.selection["rank_level"] == RANK_LEVEL
    assert settings.params.get("wind_smoothing_grid") is None  # the prior alone: nothing to choose again
    method = pool_method(settings)
    assert (method.n_perturbations, method.single_section_share) == (0, SINGLE_SECTION_SHARE)
    assert method.min_time_constants == LIMIT_TIME_CONSTANTS and method.rank_level == RANK_LEVEL


def test_twin_promise_counts_the_draws_with_enough_flags_and_bounds_the_chance_of_a_break():
    """Draws with fewer than 20 flags (or no share) are not tested; the bound is Clopper-Pearson's: the chance p
    at which k or fewer breaks in n draws have probability 5 %."""
    from scipy.stats import binom

    ok, bad = {"n_flagged": 40, "flagged_right_share": 1.0}, {"n_flagged": 25, "flagged_right_share": 0.9}
    few, none = {"n_flagged": 19, "flagged_right_share": 0.1}, {"n_flagged": 0, "flagged_right_share": float("nan")}
    p = twin_promise([ok] * 5 + [few, none])
    assert (p["tested"], p["broken"]) == (5, 0)
    assert_close(p["broken_upper"], 1 - 0.05 ** (1 / 5), what="no break in 5: the rule of three's exact form")
    p = twin_promise([ok, ok, ok, bad])
    assert (p["tested"], p["broken"]) == (4, 1)
    assert_close(binom.cdf(1, 4, p["broken_upper"]), 0.05, what="the bound solves P(X <= 1 | 4, p) = 0.05")
    assert twin_promise([bad, bad])["broken_upper"] == 1.0
    assert np.isnan(twin_promise([few, none])["broken_upper"]) and twin_promise([])["tested"] == 0


def test_twin_check_lists_the_campaigns_that_test_the_promise_beside_their_twins():
    from vivbench.validate.twin_check import TwinCheckConfig, _summary, twin_check_markdown

    def row(draw, flags, share, twin):
        actual = {m: 0.1 for m in CHECKED}
        actual.update(n_flagged=flags, flagged_right_share=share)
        expected = {m: {"predict_low": 0.0, "predict_high": 1.0} for m in CHECKED}
        return {"draw": draw, "actual": actual, "expected": expected, "inside": {m: True for m in CHECKED},
                "twin_promise": twin, "twin_nuisances": []}

    from vivbench.validate import CHECKED_METRICS as CHECKED

    rows = {0: row(0, 300, 0.40, {"tested": 5, "broken": 0, "broken_upper": 0.45}),
            1: row(1, 50, 0.99, {"tested": 3, "broken": 1, "broken_upper": 0.86}),
            2: row(2, 10, 0.10, {"tested": 0, "broken": 0, "broken_upper": float("nan")}),
            3: row(3, 80, 0.50, None)}  # journalled before the twins' promise was kept
    config = TwinCheckConfig(split="evaluation", draws=(0, 1, 2, 3), n_twins=5)
    summary = _summary(config, rows, {})
    assert [(p["draw"], p["broken"], p["twins_broken"]) for p in summary["promise"]] == [(0, True, 0), (1, False, 1)]
    page = twin_check_markdown(summary)
    assert "2 campaigns flagged enough windows to test it, 1 broke it, and the twins of 0 of those" in page
    assert "| 0 | 300 | 0.400 | yes | 5 | 0 | 45 % |" in page


def test_the_trust_section_bounds_the_chance_of_a_broken_promise(one_draw, tmp_path):
    """Twins that got every flag right give a range of 1; the report's trust section says how little that is."""
    twin = tmp_path / "twin"
    shutil.copytree(one_draw, twin)
    summary = read_twin(twin)
    draw = summary["draws"][0]
    summary["draws"] = [{**draw, "scores": {**draw["scores"], "n_flagged": 40, "flagged_right_share": share}}
                        for share in (1.0, 1.0, 1.0)]
    (twin / "twin.json").write_text(json.dumps(summary))
    section = "\n".join(twin_section(twin))
    assert "the 95 % promise held on all 3 twins that flagged enough windows to test it" in section
    assert f"at most {(1 - 0.05 ** (1 / 3)) * 100:.0f} %" in section  # 63 %: three twins vouch for little
    summary["draws"][0]["scores"]["flagged_right_share"] = 0.5
    (twin / "twin.json").write_text(json.dumps(summary))
    assert "the 95 % promise broke on 1 of the 3 twins" in "\n".join(twin_section(twin))


def test_the_twin_chooses_the_wind_smoothing_again_where_the_field_run_chose_it(field, tmp_path):
    """The model file holds the smoothing the campaign chose, pinned; the twin starts again from the prior and grid."""
    from vivbench.validate.twin_chain import pool_method, pool_settings

    root, _, results = field
    model = varying_selection(n_bootstrap=10, n_perturbations=0, wind_smoothing_grid=(10.0, 30.0))
    write_campaign_regimes(pool_results(results, model), tmp_path)
    model.save(tmp_path / MODEL_NAME)
    assert model.model_.get_params()["wind_smoothing_grid"] is None  # the chosen model holds its smoothing pinned
    settings = pool_settings(tmp_path)
    assert settings.params["wind_smoothing_s"] == 30.0 and settings.params["wind_smoothing_grid"] == [10.0, 30.0]
    rebuilt = pool_method(settings).candidates
    assert {c.model.wind_smoothing_grid for c in rebuilt if c.options["model_class"] == "varying"} == {(10.0, 30.0)}
    def grid(cands):
        return sorted(json.dumps(c.options, sort_keys=True) for c in cands)

    assert grid(rebuilt) == grid(model.candidates)  # the same options and model classes, the pooled one too


def test_the_twin_refits_a_selection_whose_choice_is_the_pooled_class_with_its_parameters(field, tmp_path):
    """A field run of the pooled class alone (its parameters given) is rebuilt as such, parameters included."""
    from vivbench.validate.twin_chain import pool_method, pool_settings

    _, _, results = field
    model = varying_selection(n_bootstrap=6, block_s=120.0, n_perturbations=0, model_classes=("pooled",),
                              wind_smoothing_s=15.0)
    write_campaign_regimes(pool_results(results, model), tmp_path)
    model.save(tmp_path / MODEL_NAME)
    settings = pool_settings(tmp_path)
    assert settings.selection["model_classes"] == ["pooled"]
    (cand,) = pool_method(settings).candidates
    assert cand.model.get_params() == model.candidates[0].model.get_params()
    assert (cand.model.n_bootstrap, cand.model.block_s, cand.model.wind_smoothing_s) == (6, 120.0, 15.0)


def test_a_twin_event_beyond_a_decks_accelerations_is_refused_so_that_the_draw_is_redrawn(field):
    from vivbench.validate.twin import _plausible

    _, events, _ = field
    event = read_event(events[0])
    assert _plausible(event) is event
    acc = event["accel"]["acc"]
    event["accel"]["acc"] = acc.copy(data=acc.values * 1e4)  # a runaway amplitude: tens of m/s^2
    with pytest.raises(InputError, match="twin event S1: .* is implausible for a bridge deck"):
        _plausible(event)
