"""The primitive types' limits, declared once in msgs._primitives, are the machine's own."""

from __future__ import annotations

import numpy

from msgs._primitives import FLOAT32_MAX, INTEGER_RANGES, SIZED_INTEGER_RANGES


def test_the_limits_are_numpys() -> None:
    """Each sized integer's range is numpy's iinfo of that type, byte and char are octets,
    and FLOAT32_MAX is numpy's largest float32."""
    assert list(SIZED_INTEGER_RANGES) == [f"{s}int{b}" for b in (8, 16, 32, 64) for s in ("", "u")]
    for name, (low, high) in SIZED_INTEGER_RANGES.items():
        info = numpy.iinfo(getattr(numpy, name))
        assert (low, high) == (int(info.min), int(info.max)), name
    assert INTEGER_RANGES["byte"] == INTEGER_RANGES["char"] == (0, 255)
    assert float(numpy.finfo(numpy.float32).max) == FLOAT32_MAX
