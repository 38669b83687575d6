"""Any number of instrumented sections >= 1: the chain with 1, 2 and 4 sections.

Each campaign is generated from a TOML configuration as a user would write it
(``[structure]`` with one mode-shape value and one tributary length per
section) and driven through the CLI subcommands synth, identify, pool,
forecast, refit and report in-process (``vivbench.cli.main``). The campaigns
are small (two 10-minute events) so that the whole file stays quick.
"""

from __future__ import annotations

import json
import re
from urllib.parse import unquote

import numpy as np
import pytest
import xarray as xr

from vivbench.core.terms import reference_section
from vivbench.synth import AeroConfig, GeneratorConfig, StructureConfig, config_from_dict, exact_coefficients
from tests.helpers import REPO, assert_close, run_cli

# Mode shapes of a half-sine (odd number of half-waves) at k / (n + 1) of the span, tributary lengths span / n.
_SPAN = 1650.0
_STEPS = ("synth", "identify", "pool", "forecast", "refit", "report")


def _structure_toml(n: int) -> str:
    x = np.arange(1, n + 1) / (n + 1)
    phi = np.round(np.sin(np.pi * x), 3)
    lengths = [_SPAN / n] * n
    return ("[structure]\n"
            f"mode_shape = [{', '.join(f'{p:g}' for p in phi)}]\n"
            f"tributary_lengths = [{', '.join(f'{v:g}' for v in lengths)}]\n")


def _run(argv: list[str]) -> tuple[int, str]:
    """Run one subcommand in-process; its exit code and stdout + stderr."""
    run = run_cli(*argv)
    return run.returncode, run.stdout + run.stderr


@pytest.fixture(scope="session", params=[1, 2, 4], ids=lambda n: f"{n}sec")
def chain(request, tmp_path_factory):
    """A two-event campaign with n sections taken through every step; exit codes, outputs and paths."""
    n = request.param
    root = tmp_path_factory.mktemp(f"sections{n}")
    cfg = root / "bridge.toml"
    cfg.write_text(_structure_toml(n))
    campaign, identify = root / "campaign", root / "identify"
    result = identify / "E001.identify.nc"
    argv = {
        "synth": ["synth", "--events", "2", "--duration", "10", "--seed", "5", "--config", str(cfg),
                  "--out", str(campaign), "--workers", "1"],
        "identify": ["identify", str(campaign), "--out", str(identify), "--workers", "1"],
        "pool": ["pool", str(identify), "--bootstrap", "5"],
        "forecast": ["forecast", str(result), "--out", str(root / "forecast"), "--campaign", str(campaign),
                     "--d", "0,50", "--horizon", "120"],
        "refit": ["refit", str(result), "--out", str(root / "refit"), "--event", str(campaign / "E001.nc"),
                  "--terms", "U^2, A, A U", "--t0", "200", "--t1", "320", "--max-iter", "30"],
        "report": ["report", "--campaign", str(campaign), "--results", str(identify), "--name", "r",
                   "--out-root", str(root / "reports"), "--forecast", str(root / "forecast"),
                   "--refit", str(root / "refit")],
    }
    out = {"n": n, "root": root, "campaign": campaign, "identify": identify, "result": result, "codes": {}, "logs": {}}
    for step in _STEPS:
        out["codes"][step], out["logs"][step] = _run(argv[step])
    return out


def _sections(n: int) -> list[str]:
    return [f"S{k + 1}" for k in range(n)]


def _ok(chain, step):
    assert chain["codes"][step] == 0, f"vivbench {step} with {chain['n']} sections:\n{chain['logs'][step]}"


def test_synth_writes_n_sections(chain):
    from vivbench.io.event import read_event

    _ok(chain, "synth")
    n = chain["n"]
    files = sorted(chain["campaign"].glob("E*.nc"))
    assert len(files) == 2 and (chain["campaign"] / "catalogue.csv").is_file()
    tree = read_event(files[0])
    assert [str(s) for s in tree["accel"]["section"].values] == _sections(n)
    assert tree["wind"]["u"].shape[1] == n and tree["accel"]["acc"].shape[1] == n
    truth = tree["truth"].ds
    assert truth["A"].shape[1] == n and truth["r"].shape[1:] == (n, 4)
    # the realistic default: no exact coefficient matrix, the truth's curves per section instead
    assert "coef" not in truth and truth["curves"].shape[:2] == (n, 4)
    cfg = json.loads(truth.attrs["config_json"])["generator"]["structure"]
    assert len(cfg["mode_shape"]) == n and len(cfg["tributary_lengths"]) == n
    # an in_library bridge with these sections has an exact (n, 23 n) coefficient matrix
    Xi = exact_coefficients(StructureConfig(**cfg), AeroConfig.in_library())
    assert Xi is not None and Xi.shape == (n, 23 * n)


def test_identify_and_pool_use_23n_columns(chain):
    _ok(chain, "identify")
    _ok(chain, "pool")
    n = chain["n"]
    with xr.open_dataset(chain["result"]) as res:
        assert res["coef"].shape[1:] == (n, 23 * n)
        assert [str(s) for s in res["equation"].values] == _sections(n)
    with xr.open_dataset(chain["identify"] / "campaign.regimes.nc") as pooled:  # the default: varying model
        assert pooled["curves"].dims[0] == "equation" and pooled["curves"].shape[0] == n
        assert [str(s) for s in pooled["equation"].values] == _sections(n)


def test_forecast_reports_every_section(chain):
    _ok(chain, "forecast")
    n = chain["n"]
    fc = chain["root"] / "forecast"
    rows = (fc / "forecast_E001.csv").read_text().splitlines()
    sections = {line.split(",")[3] for line in rows[1:]}
    assert sections == set(_sections(n))
    assert (fc / "forecast_E001.png").stat().st_size > 0
    summary = json.loads((fc / "summary.json").read_text())
    ref = f"S{reference_section(n) + 1}"
    assert f"nmse_{ref}_d0" in summary and f"campaign_model_forecast_nmse_{ref}" in summary


def test_refit_fits_every_equation(chain):
    _ok(chain, "refit")
    n = chain["n"]
    summary = json.loads((chain["root"] / "refit" / "summary.json").read_text())
    assert [summary[f"support_size_S{k + 1}"] for k in range(n)] == [3] * n
    assert f"support_size_S{n + 1}" not in summary
    assert {f"nmse_refit_S{k + 1}" for k in range(n)} <= set(summary)


def test_report_has_every_figure(chain):
    _ok(chain, "report")
    n = chain["n"]
    report = chain["root"] / "reports" / "r" / "report.md"
    text = report.read_text()
    assert "Figure not made" not in text
    for target in re.findall(r"\]\(([^)\s]+\.png)\)", text):
        assert (report.parent / unquote(target)).is_file(), target
    assert f"one of the {23 * n} library terms" in text
    assert f"dA/dt at S{reference_section(n) + 1}" in text


# ------------------------------------------------------------ configuration and helpers (no simulation)


@pytest.mark.parametrize("n", [1, 2, 4, 7])
def test_structure_config_any_section_count(n):
    cfg = config_from_dict({"structure": {"mode_shape": [1.0] * n, "tributary_lengths": [100.0] * n}})
    s = cfg.structure
    assert s.n_sections == n and s.sections == tuple(_sections(n))
    assert_close(s.positions, s.span_length * np.arange(1, n + 1) / (n + 1))
    assert_close(s.participation, np.full(n, 1.0 / n))  # beta_k = L_k phi_k / sum L phi^2


def test_example_configuration_has_four_sections():
    
    from vivbench.synth import load_config

    path = REPO / "examples" / "bridge_4_sections.toml"
    assert load_config(path).structure.sections == ("S1", "S2", "S3", "S4")


def test_default_structure_is_unchanged():
    s = GeneratorConfig().structure
    assert s.sections == ("S1", "S2", "S3")
    assert s.positions.tolist() == [412.5, 825.0, 1237.5]
    assert reference_section(3) == 1


@pytest.mark.parametrize("kwargs, match", [
    ({"mode_shape": (), "tributary_lengths": ()}, "at least one"),
    ({"mode_shape": (0.7, 1.0), "tributary_lengths": (550.0, 550.0, 550.0)}, r"one value per section \(2"),
    ({"mode_shape": (0.7, 1.0), "tributary_lengths": (550.0, -1.0)}, "positive"),
])
def test_structure_config_rejects_inconsistent_sections(kwargs, match):
    with pytest.raises(ValueError, match=match) as info:
        StructureConfig(**kwargs)
    assert "\n" not in str(info.value)


def test_reference_section_is_the_middle_one():
    assert [reference_section(n) for n in (1, 2, 3, 4, 5)] == [0, 0, 1, 1, 2]
    with pytest.raises(ValueError, match="at least one section"):
        reference_section(0)


def test_simulate_rejects_coefficients_of_the_wrong_width():
    from vivbench.models.simulate import forecast_coefficients

    res = xr.Dataset({"coef": (("window", "equation", "feature"), np.zeros((1, 2, 45))),
                      "window_start": (("window",), [0.0]), "window_end": (("window",), [50.0])})
    with pytest.raises(ValueError, match=r"\(window, S, 23 S\)"):
        forecast_coefficients(res, 0.0)
