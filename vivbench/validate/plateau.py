"""Where to forecast: the clearest self-excited plateau of an event or a campaign.

The paper forecasts event 1 from t0 = 600 s, inside a stretch "characterised
by a strong self-excited effect and a large vibration amplitude". Here that
stretch is chosen by a rule, from the truth when there is one:

- truth (:func:`truth_plateau`): the longest contiguous run of true regime 4
  (docs/concepts.md (regimes): the A^3 order matters, a VIV plateau) at the middle section
  (S2 of three, :func:`vivbench.core.terms.reference_section`; the antinode
  of the mode); ties go to the run with the larger mean true amplitude. The campaign's clearest plateau (:func:`clearest_plateau`) is the
  longest such run over all events (ties: larger amplitude, then event id).
- measurement only (:func:`measured_plateau`): the longest run in which the
  measured amplitude of the middle section stays at or above ``level`` times its maximum.

The default forecast start is one window width (50 s) after the start of the
run, so that the window models in force at t0 lie inside the plateau, unless
the run is shorter than two windows, in which case it is the run's midpoint.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr
from vivbench.core.errors import InputError

from vivbench.core.terms import reference_section
from vivbench.preprocess.runs import mask_runs

__all__ = ["Plateau", "clearest_plateau", "measured_plateau", "truth_plateau"]


@dataclass(frozen=True, kw_only=True)
class Plateau:
    """A plateau of one event.

    Attributes
    ----------
    event_id : str
    start, end : float, s
        First and last sample of the run.
    t0 : float, s
        Default forecast start inside it.
    amplitude : float, m
        Mean amplitude of the section over the run.
    source : str
        "truth" (regime 4 run) or "measured" (amplitude run).
    """

    event_id: str
    start: float
    end: float
    t0: float
    amplitude: float
    source: str

    @property
    def duration(self) -> float:
        return self.end - self.start


def _best_run(t, mask, amp, event_id, source, window):
    runs = mask_runs(mask)
    first = np.array([r.start for r in runs], dtype=int)
    last = np.array([r.stop - 1 for r in runs], dtype=int)
    if first.size == 0:
        return None
    dur = t[last] - t[first]
    mean_amp = np.array([np.nanmean(amp[a:b + 1]) for a, b in zip(first, last)])
    k = int(np.lexsort((-mean_amp, -dur))[0])
    start, end = float(t[first[k]]), float(t[last[k]])
    t0 = start + window if end - start >= 2 * window else 0.5 * (start + end)
    return Plateau(event_id=event_id, start=start, end=end, t0=t0, amplitude=float(mean_amp[k]), source=source)


def truth_plateau(truth: xr.Dataset, event_id: str = "", *, section: int | None = None,
                  window: float = 50.0) -> Plateau | None:
    """Longest run of true regime 4 at one section (default the middle one, S2 of three); None if there is none.

    Parameters
    ----------
    truth : the ``/truth`` group of an event (``time``, ``regime``, ``A``)
    event_id : str
    section : int, optional
        Index of the section (1: S2); default :func:`vivbench.core.terms.reference_section`.
    window : float, s
        Offset of the default t0 from the start of the run.
    """
    t = np.asarray(truth["time"].values, dtype=float)
    if section is None:
        section = reference_section(truth["A"].shape[1])
    regime = np.asarray(truth["regime"].values)[:, section]
    A = np.asarray(truth["A"].values, dtype=float)[:, section]
    return _best_run(t, regime == 4, A, event_id, "truth", window)


def measured_plateau(result: xr.Dataset, *, level: float = 0.8, section: int | None = None,
                     window: float = 50.0) -> Plateau:
    """Longest run with measured A at or above ``level`` times its maximum.

    Parameters
    ----------
    result : identification result (``A`` on ``time``)
    level : float in (0, 1)
    section : int, optional
        Index of the section; default the middle one (:func:`vivbench.core.terms.reference_section`).
    window : float, s
    """
    if not 0 < level < 1:
        raise InputError(f"level must lie in (0, 1); got {level}")
    t = np.asarray(result["time"].values, dtype=float)
    if section is None:
        section = reference_section(result["A"].shape[1])
    A = np.asarray(result["A"].values, dtype=float)[:, section]
    if not np.isfinite(A).any():
        raise InputError("the measured amplitude has no finite value")
    mask = np.isfinite(A) & (A >= level * np.nanmax(A))
    return _best_run(t, mask, A, str(result.attrs.get("event_id", "")), "measured", window)


def clearest_plateau(campaign_dir, *, section: int | None = None, window: float = 50.0) -> Plateau:
    """The event of a synthetic campaign with the longest true regime-4 run.

    Parameters
    ----------
    campaign_dir : path-like
        Directory of event files with ``/truth``.

    Raises
    ------
    ValueError
        No event with a truth, or no event with a regime-4 run.
    """
    from vivbench.io.event import list_events, read_event

    best, seen_truth = None, False
    for path in list_events(Path(campaign_dir)):
        tree = read_event(path)
        if "truth" not in tree.children:
            continue
        seen_truth = True
        p = truth_plateau(tree["truth"].ds, str(tree.attrs["event_id"]), section=section, window=window)
        if p is not None and (best is None or (p.duration, p.amplitude) > (best.duration, best.amplitude)):
            best = p
    if not seen_truth:
        raise InputError(f"{campaign_dir}: no event file with a truth group")
    if best is None:
        raise InputError(f"{campaign_dir}: no event has a run of true regime 4")
    return best
