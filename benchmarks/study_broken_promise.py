"""Study: what breaks the verdict's promise on a family draw: the bridge or the campaign, the wind or the buffeting.

Run::

    python benchmarks/run_study.py broken_promise --split development --draws 18 --max-duration 30 --out DIR \
        [--max-events N] [--workers 2]

On a draw whose campaign breaks the promise (fewer than 95 % of at least 20 flagged window-equations
carry the truth's regime), the study asks which part of the draw the break belongs to. It fits the
default campaign model (the held-out selection of varying-coefficient models, as ``vivbench pool``)
on campaigns that differ from the draw's in one thing each, all with the draw's caps:

- ``campaign``: the draw's own campaign;
- ``second_campaign``, ``third_campaign``, ``fourth_campaign``: the same bridge and generator, other
  campaign seeds (new wind scripts, turbulence and noise): a break that comes back belongs to the
  bridge, not to one campaign;
- ``tributary_wind``: the same campaign seed, with the deck feeling the tributary average of the
  turbulent field the anemometers sample (``felt_wind = "tributary"``) instead of a smooth wind while the
  anemometers record point turbulence it does not feel (on a draw whose deck already feels the
  tributary average it does not apply: no flags, NaN errors);
- ``no_buffeting``: the same campaign seed without buffeting;
- ``truth_wind``: the draw's own campaign fitted on the wind the truth's dynamics sees
  (:func:`vivbench.validate.record_with_truth_wind`) instead of the measured one: the errors in the wind removed,
  all else (the campaign, its identification, the buffeting) the same.

Each row also gives the bridge's envelope time constant, 1 / (2 pi f zeta) (``envelope_time_constant_s``):
the time over which the envelope follows a change of the wind it feels.

Each variant is scored against its own truth: flags, those right, the energy-weighted relative dA/dt
error on the truth's own (A, U) and the energy-weighted curve error. The study directory ``--out``
keeps each draw's campaigns, identifications and scores; rerunning with the same options continues it.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

#: Seed offsets of the other campaigns of the same bridge.
OTHER_CAMPAIGNS = {"second_campaign": 1, "third_campaign": 2, "fourth_campaign": 3}
#: The variants of a draw's campaign.
VARIANTS = ("campaign", *OTHER_CAMPAIGNS, "tributary_wind", "no_buffeting", "truth_wind")


def variant_config(campaign, name: str):
    """The draw's campaign configuration (a :class:`vivbench.synth.CampaignConfig`) changed as variant ``name``."""
    import dataclasses

    g = campaign.generator
    if name == "campaign":
        return campaign
    if name in OTHER_CAMPAIGNS:
        return dataclasses.replace(campaign, seed=campaign.seed + OTHER_CAMPAIGNS[name])
    if name == "tributary_wind":
        if g.wind.felt_wind == "tributary":
            raise ValueError("the deck already feels the tributary-averaged wind: the variant tributary_wind does "
                             "not apply")
        wind = dataclasses.replace(g.wind, felt_wind="tributary")
        return dataclasses.replace(campaign, generator=dataclasses.replace(g, wind=wind))
    if name == "no_buffeting":
        aero = dataclasses.replace(g.aero, buffeting_w=0.0, buffeting_u=0.0)
        return dataclasses.replace(campaign, generator=dataclasses.replace(g, aero=aero))
    raise ValueError(f"unknown variant {name!r}; one of {', '.join(VARIANTS)}")


def _variant_inputs(task: dict, name: str):
    """Records, truths and windows of one variant's campaign, generated and identified in ``<draw dir>/<name>``."""
    from vivbench.synth.family import draw_bridge

    from benchmarks._family_args import capped_draw, draw_dir, identified_campaign

    if name == "campaign":
        return capped_draw(task)  # the draw directory itself, as the other family studies keep it
    if name == "truth_wind":
        from vivbench.validate import record_with_truth_wind

        records, truths, windows = capped_draw(task)
        return [record_with_truth_wind(r, t) for r, t in zip(records, truths)], truths, windows
    campaign = draw_bridge(task["split"], task["draw"]).campaign_config(max_events=task["max_events"],
                                                                        max_duration=task["max_duration_s"])
    return identified_campaign(draw_dir(task) / name, variant_config(campaign, name))


def score_draw(task: dict) -> dict:
    """One draw: every variant's campaign generated, identified, fitted and scored (a stored row gains the
    variants it lacks)."""
    import math

    from vivbench.validate.methods import CampaignMethod

    from benchmarks._family_args import fit_and_score, labelled_row, store_row, stored_variants

    row, missing = stored_variants(task, VARIANTS)
    if not missing and "envelope_time_constant_s" in row:
        return row
    labels, new = labelled_row(task)
    if row is None:
        row = new
        row.update(bell=str(labels["bell"]), e_mix=str(labels["e_mix"]), buffeting_w=float(labels["buffeting_w"]),
                   point_intensity=labels["point_intensity"], point_timescale_s=labels["point_timescale_s"])
    row["envelope_time_constant_s"] = 1.0 / (2.0 * math.pi * float(labels["frequency_hz"])
                                             * float(labels["damping_ratio"]))
    for name in missing:
        if name == "tributary_wind" and row["eiv"] == "tributary":
            row.update({f"{k}_{name}": v for k, v in (("flags", 0), ("right", 0), ("error", math.nan),
                                                      ("curve_error", math.nan), ("coverage", math.nan),
                                                      ("fit_s", math.nan), ("chosen", ""), ("n_events", 0))})
            continue
        records, truths, windows = _variant_inputs(task, name)
        scores = fit_and_score(CampaignMethod("varying"), records, truths, windows)
        row.update({f"{k}_{name}": v for k, v in scores.items()}, **{f"n_events_{name}": len(records)})
    return store_row(task, row)


def summarise(rows: list[dict]) -> list[dict]:
    """One row per draw and variant: flags, those right, their share, whether the promise holds, the errors."""
    import math

    from vivbench.validate.study_report import PROMISE_MIN_FLAGS, PROMISE_SHARE

    out = []
    for r in rows:
        for name in VARIANTS:
            flags, right = int(r[f"flags_{name}"]), int(r[f"right_{name}"])
            share = right / flags if flags else math.nan
            out.append({"draw": r["draw"], "variant": name, "flags": flags, "right": right, "share_right": share,
                        "promise": ("untested" if flags < PROMISE_MIN_FLAGS else
                                    "kept" if share >= PROMISE_SHARE else "broken"),
                        "error": r[f"error_{name}"], "curve_error": r[f"curve_error_{name}"],
                        "chosen": r[f"chosen_{name}"], "envelope_time_constant_s": r["envelope_time_constant_s"],
                        "point_timescale_s": r["point_timescale_s"]})
    return out


def findings(summary: list[dict]) -> list[str]:
    """Sentences generated from the figures."""
    lines = []
    for draw in sorted({s["draw"] for s in summary}):
        of_draw = [s for s in summary if s["draw"] == draw]
        parts = [f"{s['variant']} {s['right']} of {s['flags']} right ({s['promise']}, dA/dt error {s['error']:.3f})"
                 for s in of_draw]
        point = of_draw[0]["point_timescale_s"]
        scales = (f"envelope time constant {of_draw[0]['envelope_time_constant_s']:.0f} s"
                  + ("" if point is None else f", the anemometers' point turbulence on a time scale of {point:.0f} s"))
        lines.append(f"Draw {draw} ({scales}): " + "; ".join(parts) + ".")
    counts = []
    for name in VARIANTS:
        tested = [s for s in summary if s["variant"] == name and s["promise"] != "untested"]
        broken = sum(s["promise"] == "broken" for s in tested)
        counts.append(f"{name} {broken} of {len(tested)}")
    lines.append("Broken, of the campaigns with at least 20 flags: " + "; ".join(counts) + ".")
    return lines


def main(argv=None) -> dict:
    from _family_args import family_study

    return family_study("study_broken_promise", __doc__.splitlines()[0], argv, summarise, findings,
                        max_duration=30.0)


if __name__ == "__main__":
    main()
