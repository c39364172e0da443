"""The CDR decoder's count checks at their edges (issue 54: mutation testing of msgs/cdr.py
left these unchecked): an unknown field type and a type nested past 32 levels are refused
with their names, by what a sequence's count is checked against (min_size) and by what its
elements are charged (element_cost)."""

from __future__ import annotations

from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import pytest

from msgs.cdr import CdrError, element_cost, min_size

Measure = Callable[..., int]
MEASURES = [pytest.param(min_size, id="min_size"), pytest.param(element_cost, id="element_cost")]


def _chain(depth: int) -> Callable[[str], Any]:
    """A type store where deep/T0 holds a deep/T1, ... down to deep/T<depth>, which holds an
    int32: ``depth`` levels of nesting below deep/T0."""
    def find(name: str) -> Any:
        level = int(name.rpartition("T")[2])
        fields = {"v": "int32"} if level == depth else {"x": f"deep/T{level + 1}"}
        return SimpleNamespace(_fields_and_types=fields)

    return find


@pytest.mark.parametrize("measure", MEASURES)
@pytest.mark.parametrize("spec", ["", "int32[", "[3]", "int32[]x"])
def test_an_unknown_field_type_is_refused_naming_it(measure: Measure, spec: str) -> None:
    """A field type string that is no IDL type fails as a CdrError of the whole message
    that quotes it."""
    with pytest.raises(CdrError) as info:
        measure(spec)
    assert (info.value.type_name, info.value.path) == ("?", "")
    assert str(info.value) == f"?: cannot decode the message from CDR: unknown field type {spec!r}"


@pytest.mark.parametrize("measure", MEASURES)
def test_32_levels_of_nesting_are_measured_and_33_refused(measure: Measure) -> None:
    """A type 32 levels deep is measured (as deep as a ROS type goes, and more); one 33
    levels deep is refused naming the type past the limit."""
    assert measure("deep/T0", _chain(32)) > 0
    with pytest.raises(CdrError) as info:
        measure("deep/T0", _chain(33))
    assert str(info.value) == ("deep/T33: cannot decode the message from CDR: nested more than "
                               "32 levels deep")
    assert info.value.path == ""


def test_nesting_counts_from_the_type_measured() -> None:
    """The limit counts levels below the type asked about: a chain of 32 below deep/T1 (33
    below deep/T0) is measured from deep/T1."""
    find = _chain(33)
    assert min_size("deep/T1", find) == 4 and element_cost("deep/T1", find) > 0
