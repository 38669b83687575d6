"""The report figures' common style: resolution, colours, the atomic PNG writer and section lookup.

Every report figure is drawn with matplotlib's Agg backend at a fixed size and
dpi and written atomically without a software tag or date, so the same data
give the same bytes.
"""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from vivbench.core.errors import InputError  # noqa: E402
from vivbench.core.terms import reference_section  # noqa: E402
from vivbench.io.netcdf import atomic_path  # noqa: E402

__all__ = ["DPI", "REGIME_COLOURS", "SECTION_COLOURS", "figure_file", "count_word", "section_index"]

#: Resolution of every report figure (dots per inch).
DPI = 100
#: Colours of the regimes 1..4 (same as the event overview figure).
REGIME_COLOURS = {1: "#9e9e9e", 2: "#4c9be8", 3: "#f0a030", 4: "#d62728"}
#: Colours of the sections S1..S3 in every figure.
SECTION_COLOURS = {"S1": "#1b9e77", "S2": "#d95f02", "S3": "#7570b3"}


@contextmanager
def figure_file(path, nrows=1, ncols=1, *, figsize, dpi=DPI, **kwargs):
    """Create a figure, yield (fig, axes), write it atomically and close it."""
    fig, axes = plt.subplots(nrows, ncols, figsize=figsize, **kwargs)
    try:
        yield fig, axes
        path = Path(path)
        with atomic_path(path, suffix=".png") as tmp:
            # No software tag or date in the PNG: the same data give the same bytes.
            fig.savefig(tmp, dpi=dpi, format="png", metadata={"Software": None})
    finally:
        plt.close(fig)



_COUNT_WORDS = ("one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten")


def count_word(n: int) -> str:
    """A count in words for captions and titles: 'three' for 3, digits above ten."""
    return _COUNT_WORDS[n - 1] if 1 <= n <= len(_COUNT_WORDS) else str(n)


def section_index(sections, section: str | None) -> int:
    """Index of ``section`` among ``sections``; None: the middle section (S2 of three)."""
    names = [str(s) for s in np.asarray(sections).tolist()]
    if section is None:
        return reference_section(len(names))
    if section not in names:
        raise InputError(f"section {section!r} is not in the data; sections are {names}")
    return names.index(section)

