"""The command line tells bad input (exit 2, one line) from a bug (traceback, a request to report it, exit 1)."""

from __future__ import annotations

import pytest

import vivbench
import vivbench.analysis.identify as identify_module
import vivbench.io.result as result_module
import vivbench.synth as synth_package
import vivbench.synth.campaign as campaign_module
from vivbench.cli import EXIT_INPUT, EXIT_INTERNAL, main
from vivbench.core import InputError
from vivbench.core.errors import error_line
from vivbench.io.event import EventFormatError
from vivbench.synth import CampaignConfig


def _stderr_lines(capsys) -> list[str]:
    return [line for line in capsys.readouterr().err.splitlines() if line.strip()]


def test_input_error_is_a_value_error_and_event_format_error_is_an_input_error():
    assert issubclass(InputError, ValueError)
    assert issubclass(EventFormatError, InputError)
    exc = EventFormatError("E001.nc", "missing variable /wind/u")
    assert isinstance(exc, InputError) and str(exc) == "E001.nc: missing variable /wind/u"


def test_statuses_are_distinct():
    assert EXIT_INPUT == 2 and EXIT_INTERNAL not in (0, EXIT_INPUT, 130)


def test_config_value_error_is_input_error():
    with pytest.raises(InputError, match="n_events must be in 1..100000"):
        CampaignConfig(n_events=0)


def test_synth_with_zero_events_exits_2_in_one_line(tmp_path, capsys):
    assert main(["synth", "--events", "0", "--out", str(tmp_path / "c")]) == EXIT_INPUT
    lines = _stderr_lines(capsys)
    assert len(lines) == 1, lines
    assert lines[0].startswith("vivbench synth: ") and "n_events" in lines[0]
    assert "Traceback" not in lines[0]


def test_bad_toml_value_exits_2_in_one_line_naming_the_file(tmp_path, capsys):
    bad = tmp_path / "gen.toml"
    bad.write_text("[structure]\nfrequency = -1.0\n")
    assert main(["synth", "--events", "1", "--config", str(bad), "--out", str(tmp_path / "c")]) == EXIT_INPUT
    lines = _stderr_lines(capsys)
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"vivbench synth: {bad}: "), lines


def test_bad_toml_syntax_and_missing_file_exit_2(tmp_path, capsys):
    bad = tmp_path / "gen.toml"
    bad.write_text("[structure\n")
    assert main(["synth", "--config", str(bad), "--out", str(tmp_path / "c")]) == EXIT_INPUT
    assert main(["synth", "--config", str(tmp_path / "none.toml"), "--out", str(tmp_path / "c")]) == EXIT_INPUT
    lines = _stderr_lines(capsys)
    assert len(lines) == 2 and "no such configuration file" in lines[1], lines


def test_missing_results_directory_exits_2(tmp_path, capsys):
    assert main(["pool", str(tmp_path / "nowhere")]) == EXIT_INPUT
    lines = _stderr_lines(capsys)
    assert len(lines) == 1 and lines[0].startswith("vivbench pool: "), lines


@pytest.mark.parametrize("bad", ["mode", "1,x,2", "1,-1,1"])
def test_bad_wind_weights_exit_2_in_one_line(tmp_path, capsys, bad):
    assert main(["pool", str(tmp_path), "--wind-weights", bad]) == EXIT_INPUT
    lines = _stderr_lines(capsys)
    assert len(lines) == 1 and "--wind-weights must be" in lines[0], lines


@pytest.mark.parametrize("bad", ["-1", "nan", "inf"])
def test_bad_min_time_constants_exit_2_in_one_line(tmp_path, capsys, bad):
    assert main(["pool", str(tmp_path), "--min-time-constants", bad]) == EXIT_INPUT
    lines = _stderr_lines(capsys)
    assert len(lines) == 1 and "--min-time-constants must be" in lines[0], lines


@pytest.mark.parametrize("bad", ["", "10,x", "10,-5", "nan"])
def test_bad_wind_smoothing_grid_exits_2_in_one_line(tmp_path, capsys, bad):
    assert main(["pool", str(tmp_path), "--wind-smoothing-grid", bad]) == EXIT_INPUT
    lines = _stderr_lines(capsys)
    assert len(lines) == 1 and "--wind-smoothing-grid must be" in lines[0], lines


def test_bad_wind_bins_exit_2_in_one_line(tmp_path, capsys):
    assert main(["pool", str(tmp_path), "--wind-bins", "-2"]) == EXIT_INPUT
    lines = _stderr_lines(capsys)
    assert len(lines) == 1 and "--wind-bins must be" in lines[0], lines


def test_os_error_exits_2_in_one_line(tmp_path, monkeypatch, capsys):
    def denied(*_a, **_k):
        raise PermissionError(13, "Permission denied", str(tmp_path / "r"))

    monkeypatch.setattr(result_module, "list_results", denied)
    assert main(["pool", str(tmp_path)]) == EXIT_INPUT
    lines = _stderr_lines(capsys)
    assert len(lines) == 1 and "Permission denied" in lines[0], lines


@pytest.mark.parametrize("error", [ValueError("shapes (3,) and (4,) disagree"), KeyError("coef"),
                                   TypeError("unsupported operand"), RuntimeError("impossible state")])
def test_internal_error_shows_traceback_and_asks_for_a_report(tmp_path, monkeypatch, capsys, error):
    def broken(*_a, **_k):
        raise error

    monkeypatch.setattr(result_module, "list_results", broken)
    assert main(["pool", str(tmp_path)]) == EXIT_INTERNAL
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"vivbench pool: internal error ({type(error).__name__}: "), last
    assert f"this is a bug in vivbench {vivbench.__version__}" in last
    assert "please report it with the command line and the traceback above" in last


def test_internal_error_in_synth_generation(tmp_path, monkeypatch, capsys):
    def broken(*_a, **_k):
        raise ValueError("not a user problem")

    monkeypatch.setattr(synth_package, "generate_campaign", broken)
    assert main(["synth", "--events", "1", "--out", str(tmp_path / "c")]) == EXIT_INTERNAL
    err = capsys.readouterr().err
    assert "Traceback" in err and "internal error (ValueError: not a user problem)" in err and "please report" in err


def test_error_line_labels_bugs_only():
    assert error_line(InputError("a.nc: bad\n value")) == "InputError: a.nc: bad value"
    assert error_line(FileNotFoundError("gone")) == "FileNotFoundError: gone"
    assert error_line(ValueError("boom")) == "internal error (ValueError: boom)"
    assert error_line(KeyError("k")) == "internal error (KeyError: 'k')"


def test_campaign_failure_that_is_a_bug_is_labelled_internal(tmp_path, monkeypatch):
    calls = iter([ValueError("index out of range"), InputError("event E002: the lift goes negative")])

    def broken(*_a, **_k):
        raise next(calls)

    monkeypatch.setattr(campaign_module, "generate_event", broken)
    result = campaign_module.generate_campaign(CampaignConfig(n_events=2, duration=(120.0, 120.0)), tmp_path, workers=1)
    assert sorted(result.failures.values()) == ["InputError: event E002: the lift goes negative",
                                                "internal error (ValueError: index out of range)"]


def test_identify_labels_a_per_file_bug_as_internal_and_a_refusal_not(tmp_path, monkeypatch, capsys):
    files = []
    for name in ("A.nc", "B.nc"):
        path = tmp_path / name
        path.write_bytes(b"")
        files.append(path)
    errors = {"A.nc": InputError("no valid segment is as long as one window"), "B.nc": ValueError("bad broadcast")}

    def fake_read(path, **_options):  # identification reads with truth=False
        raise errors[path.name if hasattr(path, "name") else str(path).rsplit("/", 1)[-1]]

    monkeypatch.setattr(identify_module, "read_event", fake_read)
    written, failures = identify_module.identify_files(files, tmp_path / "out")
    assert written == []
    assert failures[str(files[0])] == f"{files[0]}: no valid segment is as long as one window"
    assert failures[str(files[1])] == f"{files[1]}: internal error (ValueError: bad broadcast)"
    # From the command line: one line per file, exit 1 (some files failed), no traceback.
    assert main(["identify", str(files[0]), str(files[1]), "--out", str(tmp_path / "out2"), "--workers", "1"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error (ValueError: bad broadcast)" in err


def test_compare_cell_bug_is_labelled_internal_and_a_refusal_passes(monkeypatch):
    import vivbench.validate.compare as compare_module

    def run(error):
        def broken(_task):
            raise error
        monkeypatch.setattr(compare_module, "_run_cell", broken)
        return compare_module._run_cell_reported({})

    with pytest.raises(RuntimeError, match=r"^internal error \(KeyError: 'x'\)$"):
        run(KeyError("x"))
    with pytest.raises(InputError, match="window must be > 0 s"):
        run(InputError("window must be > 0 s"))


def test_campaign_model_without_its_variables_is_refused():
    import xarray as xr

    from vivbench.analysis.pool import with_campaign_model

    with pytest.raises(InputError, match=r"not a campaign model .*missing \['coef', 'feature'\]"):
        with_campaign_model(xr.Dataset(), xr.Dataset())


def test_wind_bins_is_off_unless_asked_and_takes_the_default_count_without_a_number():
    from vivbench.cli import _parser
    from vivbench.cli.pool import DEFAULT_WIND_BINS

    parse = _parser().parse_args
    assert parse(["pool", "results"]).wind_bins is None  # off: the campaign-wide null test alone
    assert parse(["pool", "results", "--wind-bins"]).wind_bins is DEFAULT_WIND_BINS  # WIND_BINS bins
    assert parse(["pool", "results", "--wind-bins", "4"]).wind_bins == 4


def test_pool_events_needs_its_own_out_and_known_ids(small_results, tmp_path, capsys):
    """--events refuses to overwrite the whole campaign's model and names an unknown event, in one line each."""
    _campaign, results, _files = small_results
    assert main(["pool", str(results), "--events", "E001.."]) == EXIT_INPUT
    lines = _stderr_lines(capsys)
    assert len(lines) == 1 and "give --out another directory" in lines[0], lines
    assert main(["pool", str(results), "--events", "E099", "--out", str(tmp_path / "part")]) == EXIT_INPUT
    lines = _stderr_lines(capsys)
    assert len(lines) == 1 and "'E099'" in lines[0] and str(results) in lines[0], lines
    assert not (tmp_path / "part").exists()


def test_greybox_events_names_an_unknown_event_in_one_line(small_results, tmp_path, capsys):
    _campaign, results, _files = small_results
    assert main(["greybox", str(results), "--events", "E099..", "--out", str(tmp_path / "g")]) == EXIT_INPUT
    lines = _stderr_lines(capsys)
    assert len(lines) == 1 and lines[0].startswith("vivbench greybox: ") and "'E099'" in lines[0], lines
