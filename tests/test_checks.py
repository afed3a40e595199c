"""Input validation (lubcontact.checks): one-line ValueErrors naming the field and the value."""
import numpy as np
import pytest

from lubcontact import checks


@pytest.mark.parametrize("value, shown", [("x", "'x'"), (None, ""), (3.5, "3.5"), (-1, "-1"),
                                          (float("nan"), "nan"), ([1, 2], "[1 2]")])
def test_an_integer_field_refuses_anything_but_an_integer_and_shows_it(value, shown):
    """Strings and None too (they raised numpy's TypeError, or a ValueError about converting a
    string to float, before the field's own message)."""
    with pytest.raises(ValueError, match=r"^joint: must be an integer >= 0") as error:
        checks.integer("joint", value)
    assert str(error.value).endswith(f", got {shown}" if shown else ">= 0")


@pytest.mark.parametrize("value, expected", [(3, 3), (2.0, 2), (np.array(4), 4), (np.int32(5), 5),
                                             (True, 1)])
def test_an_integer_field_takes_integral_numbers(value, expected):
    assert checks.integer("joint", value) == expected and type(checks.integer("joint", value)) is int


def test_a_required_condition_shows_a_string_value_as_it_is():
    with pytest.raises(ValueError, match=r"^fallback: must be a method, got 'nope'$"):
        checks.require(False, "fallback", "must be a method", "nope")
