"""What msgs.cdr charges against the decode budget, at the edges mutation testing found
unchecked (issue 54): a dict's size in whole allocator blocks, a fixed byte array as one
``bytes`` object, and the budget's error when nothing at all was left."""

from __future__ import annotations

import struct
import sys
from collections.abc import Callable, Iterator
from types import SimpleNamespace
from typing import Any

import pytest

from msgs import cdr
from msgs.runtime import lookup_message
from tests.msgs.test_cdr_bounds import _struct


@pytest.fixture
def budget() -> Iterator[None]:
    """Whatever a test sets, the default budget after it."""
    yield
    cdr.set_budget(cdr.DEFAULT_BUDGET)


@pytest.mark.parametrize("keys", [0, 1, 5, 6, 11, 40, 300])
def test_a_dict_is_charged_its_size_in_whole_allocator_blocks(
        keys: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """A dict of n keys, built key by key as the decoders build theirs, is charged its
    size rounded up to the allocator's 16-byte blocks (measured, not taken from the cache)."""
    monkeypatch.setattr(cdr, "_DICT_SIZES", {})
    made = {f"k{i}": i for i in range(keys)}
    charged = cdr._dict_size(keys)
    assert charged % 16 == 0
    assert sys.getsizeof(made) <= charged < sys.getsizeof(made) + 16


@pytest.mark.parametrize("element", ["uint8", "char"])
@pytest.mark.parametrize("size", [1, 16, 1000])
def test_a_fixed_byte_array_costs_one_bytes_object(element: str, size: int) -> None:
    """A fixed array of uint8 or char decodes to one bytes object: it costs that object,
    whatever its size, and nothing per element (an int8 array costs a list and its items)."""
    assert cdr.element_cost(f"{element}[{size}]") == sys.getsizeof(bytes(size))
    assert cdr.element_cost(f"int8[{size}]") > sys.getsizeof([0] * size)


@pytest.mark.parametrize("element", ["int32", "double", "int64", "string", "boolean"])
def test_a_fixed_array_costs_its_list_and_each_element_with_its_slot(element: str) -> None:
    """A fixed array of n numbers or strings costs what a list costs (a sequence's charge)
    and, per element, its slot and the element's own cost."""
    one = cdr.element_cost(element)
    whole = cdr.element_cost(f"{element}[4]")
    assert whole == cdr.element_cost(f"sequence<{element}>") + 4 * (8 + one)


def _fixed_chain(depth: int) -> Callable[[str], Any]:
    """A robot's own type store (unknown to the process-wide lookup) where fixed/T0 holds
    one fixed/T1 in a fixed array of 2, ... down to fixed/T<depth>, which holds an int32."""
    def find(name: str) -> Any:
        level = int(name.rpartition("T")[2])
        fields = {"v": "int32"} if level == depth else {"x": f"fixed/T{level + 1}[2]"}
        return SimpleNamespace(_fields_and_types=fields)

    return find


def test_a_fixed_array_s_elements_are_measured_in_the_store_given_and_nest_as_fields() -> None:
    """A fixed array of a robot's own type is measured in the robot's store (the process's
    does not know it), costing two of the element; nesting through fixed arrays counts
    like nesting through fields: 32 levels are measured, 33 refused."""
    find = _fixed_chain(1)
    assert cdr.element_cost("fixed/T0[2]", find) == cdr.element_cost("sequence<int32>") + 2 * (
        8 + cdr.element_cost("fixed/T0", find))
    assert cdr.element_cost("fixed/T0", _fixed_chain(32)) > 0
    with pytest.raises(cdr.CdrError, match="nested more than 32 levels deep"):
        cdr.element_cost("fixed/T0", _fixed_chain(33))


def test_a_budget_used_to_its_last_byte_says_none_was_left(budget: None) -> None:
    """A first sequence that takes the whole budget (10 doubles, 40 bytes each, of 400) is
    decoded; the next one's single element fails, saying 0 bytes were left."""
    cls = lookup_message(_struct(["float64[]", "float64[]"]))
    first = struct.pack("<I", 10) + bytes(4) + bytes(8 * 10)  # the doubles aligned to 8
    data = b"\x00\x01\x00\x00" + first + struct.pack("<I", 1) + bytes(4) + bytes(8)
    cdr.set_budget(cdr.Budget(per_byte=1, floor=400))
    with pytest.raises(cdr.BudgetError) as info:
        cdr.decode(data, cls)
    assert info.value.path == "f1"
    assert info.value.why == (
        f"its 1 elements would cost about 40 bytes decoded (40 bytes each), over the decode "
        f"budget of 400 bytes for a message of {len(data)} bytes (1 times its size, at least "
        "400 bytes), of which 0 bytes were left")
    cdr.set_budget(cdr.Budget(per_byte=1, floor=440))
    assert cdr.decode(data, cls)["f1"] == [0.0]
