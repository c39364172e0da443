"""CDR, the bytes ROS 2 puts on the wire, decoded in pure Python (``cbor-raw`` subscriptions).

:func:`decode` turns the serialized form of a message (XCDR1 with its 4-byte
encapsulation header, as ``rclpy.serialization.serialize_message`` gives and our
bridge sends for ``compression: cbor-raw``) into the message's wire form: the dict a
CBOR subscription gives (``uint8``/``char`` arrays as ``bytes``, other arrays as
lists, nested messages as dicts), which ``Cls.from_json`` turns into a typed
instance.

One decoder is generated per type from ``_fields_and_types`` and compiled once
(as the bridge compiles its converters); numeric arrays are read with
``array.frombytes`` (no Python object per element until ``tolist``), byte arrays are
one slice. Malformed or truncated input raises :class:`CdrError` naming the field.

Decoding costs time and memory in proportion to the bytes given, whatever they claim:
a sequence's count (read from the bytes) or a fixed array's size is checked once, before
any element is read, against what the bytes left could hold at the fewest bytes an
element takes (:func:`min_size`: an empty message counts its one placeholder byte, a
string its length and NUL), so a count of 2^32-1 in a few bytes fails at once
("claims N elements ...") rather than looping without consuming input. A bounded
sequence's count is checked against its bound too.

What the decoded form costs is bounded as well, by a :class:`Budget`: a message may cost at
most ``max(floor, per_byte * its size)`` bytes of Python objects once decoded (16 times its
size, at least 32 MiB, by default: :func:`set_budget` changes it for the process). Each
sequence or array is charged before its elements are read, its count times what one
element costs decoded (:func:`element_cost`: its slot in the list, and a message's dict,
field names and values; an empty message 72 bytes, a ``geometry_msgs/Point`` 311); arrays
that decode to one ``bytes`` (``uint8``/``char``) or typed array (numbers with ``typed``)
cost nothing per element. A message over it raises :class:`BudgetError` naming the field,
before the elements that would pass it are made: 8 MiB of one-byte structs (1.7 GB
decoded) fail at their sequence's count, while a 4 MiB ``PointCloud2`` or a 1080p
``Image`` (their data one ``bytes``) cost a few hundred bytes.

:func:`encode` is the way back, from a typed message to the bytes rclpy's serializer
gives (MockRos's ``cbor-raw`` and recordings made from it); it walks the fields
rather than compiling, as it is not on a hot path.

``decoder_for(cls, typed=cbor2.CBORTag)`` gives the form the bridge's ``compression: cbor``
sends instead: numeric arrays as RFC 8746 typed arrays (``typed(tag, little-endian bytes)``,
the CDR bytes as they are, no per-element work), ``octet`` arrays as ``bytes`` too. This
module does not import cbor2: the caller passes the tag class.
"""

from __future__ import annotations

import array
import re
import struct
import sys
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .runtime import Message, lookup_message

__all__ = ["DEFAULT_BUDGET", "TYPED_ARRAY_TAGS", "Budget", "BudgetError", "CdrError", "Typed",
           "budget", "decode", "decoder_for", "element_cost", "encode", "min_size",
           "set_budget"]

_PRIMITIVES: dict[str, tuple[str, int]] = {  # rclpy's name -> (struct code, size)
    "boolean": ("?", 1),
    "octet": ("B", 1),
    "char": ("B", 1),
    "uint8": ("B", 1),
    "int8": ("b", 1),
    "int16": ("h", 2),
    "uint16": ("H", 2),
    "int32": ("i", 4),
    "uint32": ("I", 4),
    "int64": ("q", 8),
    "uint64": ("Q", 8),
    "float": ("f", 4),
    "double": ("d", 8),
}
_ARRAY_CODES = {"int8": "b", "int16": "h", "uint16": "H", "int32": "i", "uint32": "I",
                "int64": "q", "uint64": "Q", "float": "f", "double": "d"}
_BYTES = ("uint8", "char")  # arrays of these are bytes, as in the CBOR wire form
TYPED_ARRAY_TAGS = {"int8": 72, "int16": 77, "uint16": 69, "int32": 78, "uint32": 70,
                    "int64": 79, "uint64": 71, "float": 85, "double": 86}
"""RFC 8746 tags of little-endian typed arrays, by rclpy's element name."""
Typed = Callable[[int, bytes], Any]
"""What makes a typed array from its tag and bytes (``cbor2.CBORTag``)."""
_LITTLE = sys.byteorder == "little"
_TYPE = re.compile(r"^(?:sequence<(?P<seq>[^,<>]+(?:<\d+>)?)(?:, *(?P<bound>\d+))?>|"
                   r"(?P<base>[^\[]+)(?:\[(?P<fixed>\d+)\])?)$")


class CdrError(ValueError):
    """Serialized bytes that do not decode as the type says (malformed or truncated).

    ``path`` is the field that could not be read (``header.frame_id``), ``why`` the cause,
    ``where`` (when given) which message it was, put first in the text.
    """

    def __init__(self, type_name: str, path: str, why: str, action: str = "decode", *,
                 where: str = "") -> None:
        self.type_name, self.path, self.why, self.action = type_name, path, why, action
        field = f"field {path!r}" if path else "the message"
        way = "from" if action == "decode" else "to"
        lead = f"{where}: " if where else ""  # which message: a file's, a topic's
        super().__init__(f"{lead}{type_name}: cannot {action} {field} {way} CDR: {why}")


class BudgetError(CdrError):
    """A message that would cost more decoded than its :class:`Budget` allows (valid CDR,
    refused before the elements over the budget were made)."""


@dataclass(frozen=True)
class Budget:
    """What one message may cost once decoded: at most ``max(floor, per_byte * size)``
    bytes of Python objects (see the module text and :func:`element_cost`)."""

    per_byte: int = 16
    """Decoded bytes allowed per byte of the serialized message."""
    floor: int = 32 * 1024 * 1024
    """Decoded bytes allowed whatever the message's size (small messages)."""

    def allowance(self, size: int) -> int:
        """The decoded bytes a message of ``size`` bytes may cost."""
        return max(self.floor, self.per_byte * size)

    def describe(self, size: int) -> str:
        """The budget of a message of ``size`` bytes, in words."""
        return (f"{_mib(self.allowance(size))} for a message of {_mib(size)} "
                f"({self.per_byte} times its size, at least {_mib(self.floor)})")


DEFAULT_BUDGET = Budget()
"""The budget every decoder applies unless :func:`set_budget` gave another."""
_budget = DEFAULT_BUDGET
_per_byte, _floor = _budget.per_byte, _budget.floor  # read per message: no attribute lookups


def set_budget(new: Budget) -> None:
    """Make ``new`` the budget of every message decoded from now on, in every thread (the
    bridge and the relay set it from their options at start)."""
    global _budget, _per_byte, _floor
    if new.per_byte < 1 or new.floor < 0:
        raise ValueError(f"a decode budget needs per_byte >= 1 and floor >= 0, not {new}")
    _budget = new
    _per_byte, _floor = new.per_byte, new.floor


def budget() -> Budget:
    """The budget messages are decoded within now."""
    return _budget


def _mib(n: int) -> str:
    return f"{n / (1 << 20):.1f} MiB" if n >= 1 << 20 else f"{n} bytes"


class _OverBudget(ValueError):
    """Raised inside a decoder; :func:`_fail` makes it a :class:`BudgetError`."""


def _over_budget(count: int, each: int, left: int, size: int) -> _OverBudget:
    rest = "" if left >= _budget.allowance(size) else f", of which {_mib(max(left, 0))} were left"
    return _OverBudget(
        f"its {count} elements would cost about {_mib(count * each)} decoded "
        f"({each} bytes each), over the decode budget of {_budget.describe(size)}{rest}")


def _fail(type_name: str, field: str, exc: Exception) -> CdrError:
    if isinstance(exc, CdrError):  # from a nested message: the path starts here
        return type(exc)(type_name, f"{field}.{exc.path}" if exc.path else field, exc.why)
    if isinstance(exc, _OverBudget):
        return BudgetError(type_name, field, str(exc))
    why = "truncated" if isinstance(exc, struct.error | IndexError) else str(exc)
    return CdrError(type_name, field, why)


def min_size(spec: str, find: Callable[[str], type[Message]] | None = None,
             _depth: int = 0) -> int:
    """The fewest bytes a field of IDL type ``spec`` takes in CDR, alignment aside (a lower
    bound: padding only adds). An empty message takes its one placeholder byte, so every
    type takes at least one; this is what a sequence's count is checked against. ``find``
    gives a nested type's class (default: the process-wide lookup; a decoder passes its
    class's own, so a robot's types are read in that robot's store)."""
    m = _TYPE.match(spec)
    if m is None:
        raise CdrError("?", "", f"unknown field type {spec!r}")
    if m["seq"] is not None:
        return 4
    base, fixed = m["base"], m["fixed"]
    count = int(fixed) if fixed is not None else 1
    if base in _PRIMITIVES:
        one = _PRIMITIVES[base][1]
    elif base.startswith("wstring"):
        one = 4  # the length; no terminator
    elif base.startswith("string"):
        one = 5  # the length and the NUL it counts
    else:
        if _depth > 32:  # ROS types do not nest this deep, and never in themselves
            raise CdrError(base, "", "nested more than 32 levels deep")
        fields = (find or lookup_message)(base)._fields_and_types
        one = sum(min_size(f, find, _depth + 1) for f in fields.values()) if fields else 1
    return count * max(one, 1)


# What objects take in the allocator's blocks (16-byte steps), not as sys.getsizeof says:
_SLOT = 8  # a list's pointer to each element
_LIST = 64  # an empty list
_STR = 64  # a short str (its characters are in the bytes, counted there)
_NUMBER = {"boolean": 0, "octet": 0, "char": 0, "uint8": 0,  # cached objects (int8: below)
           "int64": 48, "uint64": 48}  # others (float, int): 32
_INT = 32
_INT8_CACHED = bytes(range(0, 0x81)) + bytes(range(0xFB, 0x100))  # int8 -5..128: CPython's
# small ints; the others (-128..-6) are one int object each


def _dict_size(n: int) -> int:
    """What a dict of ``n`` keys takes, built key by key as the decoders build theirs."""
    found = _DICT_SIZES.get(n)
    if found is None:
        made: dict[str, None] = {}
        for i in range(n):
            made[f"f{i}"] = None
        found = _DICT_SIZES[n] = -(-sys.getsizeof(made) // 16) * 16
    return found


_DICT_SIZES: dict[int, int] = {}


def element_cost(spec: str, find: Callable[[str], type[Message]] | None = None,
                 _depth: int = 0) -> int:
    """What one value of IDL type ``spec`` costs decoded, in bytes (an upper estimate, its
    slot in a list aside), in the allocator's 16-byte blocks: a number its object (32, 48 for
    a 64-bit integer, 0 for ``bool`` and ``uint8``, as CPython shares those), a string 64 (its
    characters are in the message's bytes), a message its dict, its field names (as an
    encoding repeats them) and its fields' values; a sequence inside it its list alone (its
    elements are charged when their count is read). This, plus 8 for the slot, is what an
    element of an array is charged against the :class:`Budget`."""
    m = _TYPE.match(spec)
    if m is None:
        raise CdrError("?", "", f"unknown field type {spec!r}")
    if m["seq"] is not None:
        return _LIST
    base, fixed = m["base"], m["fixed"]
    if fixed is not None:
        if base in _BYTES:
            return 33 + int(fixed)
        return _LIST + int(fixed) * (_SLOT + element_cost(base, find, _depth))
    if base in _PRIMITIVES:
        return _NUMBER.get(base, _INT)
    if base.startswith(("string", "wstring")):
        return _STR
    if _depth > 32:  # ROS types do not nest this deep, and never in themselves
        raise CdrError(base, "", "nested more than 32 levels deep")
    fields = (find or lookup_message)(base)._fields_and_types
    return _dict_size(len(fields)) + sum(len(name) + 4 + element_cost(f, find, _depth + 1)
                                         for name, f in fields.items())


def _claims(count: int, each: int, left: int) -> ValueError:
    """The error of a sequence or array whose elements cannot all be in the bytes left."""
    return ValueError(f"claims {count} elements of at least {each} byte"
                      f"{'s' if each > 1 else ''} each, but {max(left, 0)} bytes are left")


def _over_bound(count: int, bound: int) -> ValueError:
    return ValueError(f"claims {count} elements, over the sequence's bound of {bound}")


def _wide(data: Any) -> str:
    """A wstring's characters: UTF-16 code units stored in 4 bytes each."""
    units = array.array("I")
    units.frombytes(bytes(data))
    if not _LITTLE:
        units.byteswap()
    if units and max(units) > 0xFFFF:
        raise ValueError(f"a wide character's code unit 0x{max(units):x} is over 0xffff")
    return array.array("H", units.tolist()).tobytes().decode("utf-16-le" if _LITTLE
                                                             else "utf-16-be")


class _Gen:
    """Writes the source of one type's decoder."""

    def __init__(self, typed: Typed | None, find: Callable[[str], type[Message]]) -> None:
        self.typed = typed
        self.find = find  # the nested types' classes: the decoded class's own lookup
        self.lines: list[str] = []
        self.ns: dict[str, Any] = {
            "unpack_from": struct.unpack_from, "array": array.array, "bytes": bytes,
            "LITTLE": _LITTLE, "CdrError": CdrError, "StructError": struct.error,
            "wide": _wide, "typed": typed, "claims": _claims, "over_bound": _over_bound,
            "over_budget": _over_budget, "INT8_CACHED": _INT8_CACHED,
        }
        self.n = 0

    def var(self) -> str:
        self.n += 1
        return f"v{self.n}"

    def emit(self, depth: int, line: str) -> None:
        self.lines.append("    " * depth + line)

    def align(self, depth: int, size: int) -> None:
        if size > 1:
            self.emit(depth, f"o += (4 - o) % {size}")

    def scalar(self, depth: int, base: str, target: str) -> None:
        if base in _PRIMITIVES:
            code, size = _PRIMITIVES[base]
            self.align(depth, size)
            self.emit(depth, f"{target} = unpack_from('<{code}', b, o)[0]")
            self.emit(depth, f"o += {size}")
        elif base in ("string", "wstring") or base.startswith(("string<", "wstring<")):
            wide = base.startswith("w")
            self.align(depth, 4)
            n = self.var()
            self.emit(depth, f"{n} = unpack_from('<I', b, o)[0]")
            if wide:  # Fast-CDR: UTF-16 code units of 4 bytes each, no terminator
                self.emit(depth, f"if o + 4 + 4 * {n} > len(b): raise IndexError")
                self.emit(depth, f"{target} = wide(b[o + 4:o + 4 + 4 * {n}])")
                self.emit(depth, f"o += 4 + 4 * {n}")
            else:  # the length counts the NUL at the end
                self.emit(depth, f"if {n} < 1 or o + 4 + {n} > len(b): raise IndexError")
                self.emit(depth, f"{target} = bytes(b[o + 4:o + 3 + {n}]).decode()")
                self.emit(depth, f"o += 4 + {n}")
        else:
            fn = self.nested(base)
            if self.ns[fn].charges:
                self.emit(depth, f"{target}, o, r = {fn}(b, o, r)")
            else:
                self.emit(depth, f"{target}, o = {fn}(b, o)")

    def members(self, depth: int, fields: dict[str, str], out: str, prefix: str) -> None:
        """Decode ``fields`` into the dict ``out``: runs of same-size primitives with one
        ``unpack_from``, nested messages inline (no call per nested message)."""
        if not fields:  # an empty message has one placeholder byte
            self.emit(depth, "if o >= len(b): raise IndexError")
            self.emit(depth, "o += 1")
        items = list(fields.items())
        i = 0
        while i < len(items):
            name, spec = items[i]
            self.emit(depth, f"field = {prefix + name!r}")
            if spec in _PRIMITIVES:
                size = _PRIMITIVES[spec][1]
                run = [name]
                while (i + len(run) < len(items) and items[i + len(run)][1] in _PRIMITIVES
                       and _PRIMITIVES[items[i + len(run)][1]][1] == size):
                    run.append(items[i + len(run)][0])
                codes = "".join(_PRIMITIVES[fields[n]][0] for n in run)
                self.align(depth, size)
                targets = ", ".join(f"{out}[{n!r}]" for n in run)
                self.emit(depth, f"{targets}{',' if len(run) == 1 else ''} = "
                                 f"unpack_from('<{codes}', b, o)")
                self.emit(depth, f"o += {size * len(run)}")
                i += len(run)
                continue
            if _TYPE.match(spec) and "/" in spec and "[" not in spec and "<" not in spec:
                inner = self.var()
                self.emit(depth, f"{inner} = {out}[{name!r}] = {{}}")
                self.members(depth, self.find(spec)._fields_and_types, inner,
                             f"{prefix}{name}.")
            else:
                self.field(depth, name, spec, f"{out}[{name!r}]")
            i += 1

    def charge(self, depth: int, count: str, each: int, extra: str = "") -> None:
        """Take ``count`` elements of ``each`` bytes (and ``extra``) from the budget left,
        ``r``; past it, fail before they are made."""
        self.emit(depth, f"r -= {count} * {each}{extra}")
        self.emit(depth, f"if r < 0: raise over_budget({count}, {each}, "
                         f"r + {count} * {each}{extra}, len(b))")

    def nested(self, type_name: str) -> str:
        name = "d_" + re.sub(r"\W", "_", type_name)
        self.ns[name] = _decoder_with_offset(self.find(type_name), self.typed)
        return name

    def field(self, depth: int, name: str, spec: str, target: str) -> None:
        m = _TYPE.match(spec)
        if m is None:
            raise CdrError("?", name, f"unknown field type {spec!r}")
        base = m["seq"] or m["base"]
        count: str | None = None
        if m["seq"] is not None:
            self.align(depth, 4)
            count = self.var()
            self.emit(depth, f"{count} = unpack_from('<I', b, o)[0]")
            self.emit(depth, "o += 4")
            if m["bound"] is not None:
                self.emit(depth, f"if {count} > {m['bound']}: "
                                 f"raise over_bound({count}, {m['bound']})")
        elif m["fixed"] is not None:
            count = m["fixed"]
        if count is None:
            self.scalar(depth, base, target)
            return
        if base in _BYTES or base in _ARRAY_CODES or base == "octet" or base == "boolean":
            size = _PRIMITIVES[base][1]
            if size > 1:
                self.emit(depth, f"if {count}: o += (4 - o) % {size}")
            end = self.var()
            self.emit(depth, f"{end} = o + {count} * {size}")
            self.emit(depth, f"if {end} > len(b): raise claims({count}, {size}, len(b) - o)")
            if base in _BYTES or (self.typed is not None and base == "octet"):
                self.emit(depth, f"{target} = bytes(b[o:{end}])")
            elif self.typed is not None and base in TYPED_ARRAY_TAGS:  # CDR is little-endian
                self.emit(depth, f"{target} = typed({TYPED_ARRAY_TAGS[base]}, bytes(b[o:{end}]))")
            elif base in ("octet", "boolean"):
                cast = "bool" if base == "boolean" else ""
                self.charge(depth, count, _SLOT)
                self.emit(depth, f"{target} = [{cast}(x) for x in bytes(b[o:{end}])]")
            elif m["fixed"] is not None and int(count) <= 32:  # small: one unpack_from (its
                code = _PRIMITIVES[base][0]  # cost is the type's, not the bytes')
                self.emit(depth, f"{target} = list(unpack_from('<{count}{code}', b, o))")
            else:
                if base == "int8":  # small ints are shared: the others are charged by count
                    self.charge(depth, count, _SLOT, f" + {_INT} * len(bytes(b[o:{end}])"
                                                     ".translate(None, INT8_CACHED))")
                else:
                    self.charge(depth, count, _SLOT + _NUMBER.get(base, _INT))
                arr = self.var()
                self.emit(depth, f"{arr} = array('{_ARRAY_CODES[base]}')")
                self.emit(depth, f"{arr}.frombytes(b[o:{end}])")
                self.emit(depth, f"if not LITTLE: {arr}.byteswap()")
                self.emit(depth, f"{target} = {arr}.tolist()")
            self.emit(depth, f"o = {end}")
            return
        each = min_size(base, self.find)  # checked once: the loop ends within the bytes
        self.emit(depth, f"if {count} * {each} > len(b) - o: "
                         f"raise claims({count}, {each}, len(b) - o)")
        self.charge(depth, count, _SLOT + element_cost(base, self.find))
        items = self.var()
        self.emit(depth, f"{items} = []")
        self.emit(depth, f"for _ in range({count}):")
        item = self.var()
        self.scalar(depth + 1, base, item)
        self.emit(depth + 1, f"{items}.append({item})")
        self.emit(depth, f"{target} = {items}")


_Decoder = Callable[..., Any]
"""``fn(buffer, offset[, budget left]) -> (wire dict, offset after it[, budget left])``."""
_DECODERS: weakref.WeakKeyDictionary[type[Message], dict[Typed | None, _Decoder]] = (
    weakref.WeakKeyDictionary())  # a class a relay released takes its decoders along


def _decoder_with_offset(cls: type[Message], typed: Typed | None = None) -> _Decoder:
    """``fn(buffer, offset, budget left) -> (wire dict, offset after it, budget left)`` for
    ``cls`` (compiled once per ``typed``) when ``fn.charges``; for a type that cannot take
    from the budget (no sequences or large arrays) ``fn(buffer, offset) -> (wire dict,
    offset after it)``."""
    mine = _DECODERS.setdefault(cls, {})
    found = mine.get(typed)
    if found is not None:
        return found
    gen = _Gen(typed, cls._lookup)
    gen.members(2, cls._fields_and_types, "out", "")
    charges = _charges(gen.lines)
    budget = ", r" if charges else ""  # a type that cannot charge keeps the plain signature
    gen.lines = [f"def decode(b, o{budget}):", "    out = {}", "    field = ''", "    try:",
                 *gen.lines,
                 "    except (CdrError, StructError, ValueError, IndexError) as exc:",
                 "        raise fail(TYPE, field, exc) from None", f"    return out, o{budget}"]
    gen.ns["fail"] = _fail
    gen.ns["TYPE"] = cls._type
    exec(compile("\n".join(gen.lines), f"<cdr {cls._type}>", "exec"), gen.ns)
    fn: _Decoder = gen.ns["decode"]
    fn.charges = charges  # type: ignore[attr-defined]
    mine[typed] = fn
    return fn


def _charges(lines: list[str]) -> bool:
    """Whether generated code takes from the budget (itself, or through a nested decoder)."""
    return any("r -= " in line or ", r)" in line for line in lines)


def decoder_for(cls: type[Message], typed: Typed | None = None
                ) -> Callable[[bytes | memoryview], dict[str, Any]]:
    """``fn(serialized) -> wire dict`` for messages of ``cls``; with ``typed``, numeric
    arrays as typed arrays (see the module docstring). Within the :class:`Budget` in force
    when it is called (:class:`BudgetError` past it)."""
    inner = _decoder_with_offset(cls, typed)

    def check(data: bytes | memoryview) -> None:
        if len(data) < 4:
            raise CdrError(cls._type, "", f"{len(data)} bytes are too few for CDR")
        raise CdrError(cls._type, "", "only little-endian CDR is decoded "
                       f"(encapsulation {bytes(data[:2]).hex()})")

    if not inner.charges:  # type: ignore[attr-defined]
        def decode_one(data: bytes | memoryview) -> dict[str, Any]:
            if len(data) < 4 or data[1] != 1:  # 0x00 0x01: CDR little-endian
                check(data)
            out: dict[str, Any] = inner(data, 4)[0]
            return out

        return decode_one

    def decode_within(data: bytes | memoryview) -> dict[str, Any]:
        if len(data) < 4 or data[1] != 1:
            check(data)
        left = _per_byte * len(data)
        out: dict[str, Any] = inner(data, 4, left if left > _floor else _floor)[0]
        return out

    return decode_within


def decode(data: bytes | memoryview, cls: type[Message]) -> dict[str, Any]:
    """The wire form of one serialized message of ``cls``."""
    return decoder_for(cls)(data)


def encode(msg: Message) -> bytes:
    """The serialized form of ``msg`` (little-endian CDR with its encapsulation header),
    byte for byte what ``rclpy.serialization.serialize_message`` gives for it."""
    out = bytearray(b"\x00\x01\x00\x00")
    _encode_members(out, msg)
    return bytes(out)


def _pad(out: bytearray, size: int) -> None:
    if size > 1:
        out += bytes((4 - len(out)) % size)


def _encode_members(out: bytearray, msg: Message) -> None:
    fields = msg._fields_and_types
    if not fields:  # an empty message has one placeholder byte
        out.append(0)
    for name, spec in fields.items():
        try:
            _encode_field(out, spec, getattr(msg, name))
        except CdrError as exc:  # from a nested message: the path starts here
            raise CdrError(msg._type, f"{name}.{exc.path}", exc.why, "encode") from None
        except (struct.error, TypeError, ValueError, OverflowError) as exc:
            raise CdrError(msg._type, name, str(exc), "encode") from None


def _encode_field(out: bytearray, spec: str, value: Any) -> None:
    m = _TYPE.match(spec)
    if m is None:
        raise ValueError(f"unknown field type {spec!r}")
    base = m["seq"] or m["base"]
    if m["seq"] is None and m["fixed"] is None:
        _encode_scalar(out, base, value)
        return
    if m["seq"] is not None:
        _pad(out, 4)
        out += struct.pack("<I", len(value))
    if base in _BYTES or base == "octet":
        out += bytes(value)
    elif base == "boolean":
        out += bytes(bool(v) for v in value)
    elif base in _ARRAY_CODES:
        if len(value):
            _pad(out, _PRIMITIVES[base][1])
            values = array.array(_ARRAY_CODES[base], value)
            if not _LITTLE:
                values.byteswap()
            out += values.tobytes()
    else:
        for item in value:
            _encode_scalar(out, base, item)


def _encode_scalar(out: bytearray, base: str, value: Any) -> None:
    if base in _PRIMITIVES:
        code, size = _PRIMITIVES[base]
        _pad(out, size)
        out += struct.pack("<" + code, value)
    elif base.startswith("wstring"):
        units = str(value).encode("utf-16-le")
        _pad(out, 4)
        out += struct.pack("<I", len(units) // 2)
        codes = array.array("H", units)
        out += array.array("I", codes.tolist()).tobytes() if _LITTLE else bytes(
            b for c in codes.tolist() for b in struct.pack("<I", c))
    elif base.startswith("string"):
        data = str(value).encode()
        _pad(out, 4)
        out += struct.pack("<I", len(data) + 1)
        out += data
        out.append(0)
    else:
        _encode_members(out, value)
