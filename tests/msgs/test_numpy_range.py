"""numpy integers meet the same range checks as Python ints (issue 54: a numpy value once
skipped the range check, and ``Int8(data=np.int64(1000))`` built and published)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from msgs._primitives import SIZED_INTEGER_RANGES
from msgs.runtime import ValidationError
from msgs.std_msgs.msg import Int8
from msgs.test_msgs.msg import BasicTypes
from roslibpy_lite.exceptions import InvalidMessageError
from roslibpy_lite.mock import MockRos

FIELDS = {f"{kind}_value": kind for kind in SIZED_INTEGER_RANGES}
"""BasicTypes' integer fields, each with its type (int8_value: int8 ...)."""


def _numpy_forms(value: int) -> list[Any]:
    """``value`` as the numpy scalars that can hold it: a signed or unsigned 64-bit integer
    when it fits one, an integral float64, and a 0-d array."""
    forms: list[Any] = [np.float64(value)]
    if -(2**63) <= value < 2**63:
        forms += [np.int64(value), np.array(value, dtype=np.int64)]
    if 0 <= value < 2**64:
        forms += [np.uint64(value), np.array(value, dtype=np.uint64)]
    return forms


@pytest.mark.parametrize("field", sorted(FIELDS))
def test_an_out_of_range_numpy_integer_is_refused_when_built(field: str) -> None:
    """One past either end of the field's range, as every numpy form, raises at construction
    naming the field, its type and the range."""
    low, high = SIZED_INTEGER_RANGES[FIELDS[field]]
    for value in (low - 1, high + 1):
        for form in _numpy_forms(value):
            if float(form) in (low, high):
                continue  # float64 cannot tell 2**64 from 2**64 - 1: no case for this bound
            with pytest.raises(ValidationError, match=rf"^{field}: expected {FIELDS[field]}, "
                                                      r".* is out of range"):
                BasicTypes(**{field: form})


@pytest.mark.parametrize("field", sorted(FIELDS))
def test_a_numpy_integer_in_range_is_accepted(field: str) -> None:
    """Both ends of the range, as numpy values, are accepted when built (kept as given) and
    go to the wire as those numbers."""
    for value in SIZED_INTEGER_RANGES[FIELDS[field]]:
        for form in _numpy_forms(value)[1:]:  # the exact integer forms
            msg = BasicTypes(**{field: form})
            assert getattr(msg, field) == value, form
            assert msg.to_json()[field] == value, form


async def test_an_out_of_range_numpy_integer_is_not_published() -> None:
    """A message whose field was set to an out-of-range numpy integer after it was built is
    refused by publish (InvalidMessageError naming the field), and nothing is published."""
    async with MockRos() as ros:
        pub = await ros.advertise("/numpy_range", Int8)
        msg = Int8(data=np.int64(100))  # type: ignore[arg-type]
        assert msg.data == 100
        msg.data = np.int64(1000)  # type: ignore[assignment]
        with pytest.raises(InvalidMessageError, match=r"data: expected int8, 1000 is out of range"):
            await pub.publish(msg)
        assert ros.published("/numpy_range") == []
