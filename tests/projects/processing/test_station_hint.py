"""The surveyor's word on where set-up 1 stood: parsed once, read only for set-up 1."""
from __future__ import annotations

import pytest

from common.errors import InputError
from projects.processing.parameters import parameter
from projects.processing.stages import _station_hint


def test_the_station_is_two_numbers_or_none():
    p = parameter("station_xy")
    assert p.default is None and p.stage == "plan" and p.value_of("12.5, -8") == "12.5,-8"
    assert p.value_of("none") is None
    for bad in ("12", "1,2,3", "a,b", "nan,1"):
        with pytest.raises(InputError, match="station_xy"):
            p.value_of(bad)


def test_only_set_up_1_takes_it():
    assert _station_hint(1, {"station_xy": "12.5,-8"}) == (12.5, -8.0)
    assert _station_hint(2, {"station_xy": "12.5,-8"}) is None and _station_hint(1, {"station_xy": None}) is None
