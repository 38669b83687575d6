"""Choosing a campaign's events by id and range (``--events`` of vivbench pool and greybox)."""

from __future__ import annotations

from pathlib import Path

import pytest

from vivbench.core.errors import InputError
from vivbench.io.result import select_results

FILES = [Path("/data/results") / f"E{i:03d}.identify.nc" for i in range(1, 9)]


def _ids(files) -> list[str]:
    return [f.name.removesuffix(".identify.nc") for f in files]


@pytest.mark.parametrize("spec, expected", [
    ("E003", ["E003"]),
    ("E007..", ["E007", "E008"]),
    ("..E002", ["E001", "E002"]),
    ("E002..E004", ["E002", "E003", "E004"]),
    ("E006,E001", ["E001", "E006"]),  # the campaign's order, not the spec's
    ("E001..E002, E002..E003", ["E001", "E002", "E003"]),  # overlaps counted once
    ("..", [f"E{i:03d}" for i in range(1, 9)]),
])
def test_ids_and_ranges_keep_the_campaigns_order(spec, expected):
    assert _ids(select_results(FILES, spec)) == expected


def test_the_two_sides_of_a_located_change_partition_the_campaign():
    before, after = select_results(FILES, "..E004"), select_results(FILES, "E005..")
    assert _ids(before) + _ids(after) == _ids(FILES)


@pytest.mark.parametrize("spec, says", [
    ("E009", "no identification result of event 'E009'"),
    ("E002..E010", "'E010'"),
    ("E005..E002", "starts after it ends"),
    (" , ", "at least one event"),
])
def test_bad_selections_are_refused_naming_what_is_wrong(spec, says):
    with pytest.raises(InputError, match=says.replace("(", r"\(")) as err:
        select_results(FILES, spec)
    assert "\n" not in str(err.value)


def test_nothing_to_choose_from_is_refused():
    with pytest.raises(InputError, match="no identification results"):
        select_results([], "E001..")
