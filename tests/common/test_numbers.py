"""common.numbers: the precision of a printed number by its unit."""
import doctest

import common.numbers as numbers
from common.numbers import shown, written


def test_the_examples_hold():
    assert doctest.testmod(numbers).failed == 0


def test_millimetres_and_other_units():
    assert shown("sigma_mm", 0.2055) == "0.21" and shown("displacement_mm", -0.001) == "0.00"
    assert shown("epoch", 3.0) is None and shown("sigma_mm", float("nan")) is None
    assert written("sigma_mm", 0.20549) == 0.205 and written("label", 0.123456) == 0.123456
    assert written("alarm_mm", None) is None and written("alarm_mm", 40) == 40
