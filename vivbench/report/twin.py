"""The report's "How far to trust this" section, from the output directory of ``vivbench twin``."""

from __future__ import annotations

import math
from pathlib import Path

from vivbench.report.tables import md_table, produced_by
from vivbench.validate.twin import METRIC_NAMES, read_twin, twin_promise

__all__ = ["twin_section"]

_HEADLINE = ("flagged_right_share", "coverage", "rhs_error_true_AU_energy", "rhs_error_true_AU_median",
             "curve_error_linear", "curve_error_total", "curve_error_energy")


def _fmt(x) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.3g}"


def _nuisance_counts(summary: dict) -> str:
    """`` (here: the deck felt a smooth wind in 2 of 5 twins, a yaw effect acted in 3)`` from the draws' nuisances."""
    drawn = [r["nuisances"] for r in summary["draws"] if r.get("nuisances")]
    if not drawn:
        return ""
    smooth = sum(n["felt_wind"] == "smooth" for n in drawn)
    yaw = sum(n["yaw_shape"] != "absent" for n in drawn)
    return f" (here: the deck felt a smooth wind in {smooth} of {len(drawn)} twins, a yaw effect acted in {yaw})"


def twin_section(directory, command: str | None = None) -> list[str]:
    """Markdown lines: the twin's expected recovery on this campaign and what it mirrored and assumed.

    Parameters
    ----------
    directory : output directory of ``vivbench twin`` (its ``twin.json``)
    command : the command that wrote it (default: read from ``command.txt`` there, else its canonical form)
    """
    directory = Path(directory)
    summary = read_twin(directory)
    if command is None:
        recorded = directory / "command.txt"
        command = (recorded.read_text().strip() if recorded.is_file()
                   else f"vivbench twin <campaign> <results> --bridge <bridge.toml> --out {directory}")
    m, exp = summary["mirror"], summary["expected"]
    n = len(summary["draws"])
    rows = [[METRIC_NAMES[k], _fmt(exp[k]["median"]), f"{_fmt(exp[k]['predict_low'])} - {_fmt(exp[k]['predict_high'])}",
             str(exp[k]["n"])] for k in _HEADLINE if k in exp]
    lines = [
        "## How far to trust this", "",
        f"A synthetic twin of this campaign (`{directory}`): {n} synthetic campaign{'s' if n != 1 else ''} with "
        f"its {m['n_events']} events, sections ({', '.join(m['sections'])}), rates ({m['wind_rate_hz']:g} Hz wind, "
        f"{m['accel_rate_hz']:g} Hz acceleration), measured mean wind and yaw histories, turbulence intensity "
        f"({m['turbulence_intensity']:.3f}) and noise floor ({m['noise_density_ug_rthz']:.3g} micro-g/sqrt(Hz)), "
        "with aerodynamic functions drawn from this campaign's model within its bands, were put through the same "
        "chain with the same settings and scored against their known truth. The figures below are what to expect of "
        "the chain on this bridge; the 90 % range is where one more campaign's figure falls (normal-theory "
        "prediction over the draws, of the logarithm for the errors).", "",
        md_table(["figure", "expected (median)", "90 % range of a campaign", "draws"], rows), "",
    ]
    promise = twin_promise([d["scores"] for d in summary["draws"]])
    if promise["tested"]:
        k, t = promise["broken"], promise["tested"]
        verdict = (f"the 95 % promise held on all {t} twin{'s' if t != 1 else ''} that flagged enough windows to test "
                   "it" if k == 0 else f"the 95 % promise broke on {k} of the {t} twins that flagged enough windows to "
                   "test it: read the flagged regimes with care")
        lines += [f"Flagged regimes: {verdict}; a campaign like this one breaks it with a chance of at most "
                  f"{promise['broken_upper'] * 100:.0f} % (one-sided 95 % bound over the twins: few twins bound it "
                  "loosely).",
                  ""]
    elif exp.get("coverage", {}).get("n", 0) and exp["coverage"]["predict_high"] == 0:
        lines += ["Flagged regimes: the twins flag no window; this campaign's regimes are not expected to be "
                  "identifiable.", ""]
    drawn = ("each twin draws what the records cannot tell (the errors in the wind the deck feels, buffeting, a yaw "
             "effect along the measured yaws) from the generator family's priors" + _nuisance_counts(summary)
             if summary["config"].get("priors")
             else "buffeting and the wind the deck feels are the generator's defaults, without a yaw effect")
    lines += ["What the twin assumes: the bridge file's structural properties, the generator's shapes for the "
              f"aerodynamic functions fitted to this campaign's curves; {drawn}. Where the campaign model is far "
              "from the bridge's truth the twin inherits its error and is optimistic (docs/field_workflow.md).", "",
              produced_by(command, "(twin.json)"), ""]
    if summary["failed"]:
        lines += [f"Twin draws that failed: {', '.join(map(str, summary['failed']))}.", ""]
    return lines
