"""Chosen fields of CDR messages, read straight from the bytes (tables of recordings).

:func:`leaf_names` lists a type's fields as :func:`roslibpy_lite.data.flatten` names them
(nested messages under dotted names, arrays as one value each); :func:`row_decoder`
compiles, once per type and list of names, a function ``row(serialized) -> tuple`` giving
those fields' values and nothing else: no dict, no typed message, no value for a field not
asked for.

The offsets of fixed-size fields are worked out when the function is compiled: a run of
them costs one ``Struct.unpack_from`` (skipped bytes are pad bytes of its format), and the
only work done per message in between is reading the length of each string or sequence
that comes before a chosen field (that is what moves the fields after it). A field not
asked for is stepped over: a string or a sequence of numbers by its length, without
reading its contents. The values are those :func:`msgs.cdr.decode` and ``from_json``
give (``uint8``/``char`` arrays as ``bytes``, other arrays as lists, arrays of messages as
typed messages), so a table built from either is the same.

A message the bytes cannot hold (truncated, a count past its end, not little-endian CDR)
raises from the function (``struct.error``, ``IndexError``, ``ValueError``, ``CdrError``);
the caller decodes that one message with :func:`msgs.cdr.decode` to name the field.
As there, a count read from the bytes is checked against what the bytes left can hold
before anything is read or allocated for it, and the arrays a row decodes are charged
against the message's :class:`msgs.cdr.Budget` (an array stepped over costs nothing);
past it the row raises (a ``ValueError``), and :func:`msgs.cdr.decode` names the field.
"""

from __future__ import annotations

import re
import struct
import weakref
from collections.abc import Callable, Sequence
from typing import Any

from . import cdr
from .runtime import Message

__all__ = ["RowDecoder", "fixed_offsets", "leaf_names", "row_decoder", "string_leaves"]

RowDecoder = Callable[[Any], tuple[Any, ...]]
"""``row(serialized message) -> the chosen fields' values, in the order asked for``."""


def _nested(spec: str) -> bool:
    """A field that is one nested message (not an array of them)."""
    return "/" in spec and "[" not in spec and "<" not in spec


def leaf_names(cls: type[Message]) -> list[tuple[str, str]]:
    """``(dotted name, IDL type)`` of every leaf field of ``cls``, in flatten's order."""
    out: list[tuple[str, str]] = []

    def walk(fields: dict[str, str], find: Callable[[str], type[Message]],
             prefix: str) -> None:
        for name, spec in fields.items():
            if _nested(spec):
                inner = find(spec)
                walk(inner._fields_and_types, inner._lookup, f"{prefix}{name}.")
            else:
                out.append((prefix + name, spec))

    walk(cls._fields_and_types, cls._lookup, "")
    return out


class _RowGen(cdr._Gen):
    """Writes the source of one row decoder: ``o`` is the dynamic offset, ``c`` a static
    one added to it, ``known`` the alignment ``o - 4`` is known to have."""

    def __init__(self, cls: type[Message], wanted: Sequence[str]) -> None:
        super().__init__(None, cls._lookup)
        self.slots: dict[str, list[int]] = {}
        for i, name in enumerate(wanted):
            self.slots.setdefault(name, []).append(i)
        self.values = ["None"] * len(wanted)
        self.c = 0
        self.known = 8
        self.pending: list[tuple[int, str, int, str]] = []  # offset, code, count, name
        self.bytes_leaf: set[str] = set()  # fixed uint8/char arrays: bytes, not lists
        self.structs = 0

    # -- static offsets -------------------------------------------------------------
    def flush(self) -> None:
        """Read the pending fixed-size fields (one unpack) and fold ``c`` into ``o``."""
        if self.pending:
            fmt, at, names = "<", 0, []
            for offset, code, count, name in sorted(self.pending):
                if offset > at:
                    fmt += f"{offset - at}x"
                fmt += f"{count if count > 1 else ''}{code}"
                at = offset + count * struct.calcsize(code)
                names.append((name, code, count))
            self.structs += 1
            s, t = f"S{self.structs}", self.var()
            self.ns[s] = struct.Struct(fmt)
            self.emit(1, f"{t} = {s}.unpack_from(b, o)")
            i = 0
            for name, _code, count in names:
                if count == 1:
                    self.take(name, f"{t}[{i}]")
                elif name in self.bytes_leaf:
                    self.take(name, f"bytes({t}[{i}:{i + count}])")
                else:
                    self.take(name, f"list({t}[{i}:{i + count}])")
                i += count
            self.pending = []
        if self.c:
            self.emit(1, f"o += {self.c}")
            self.known = min(self.known, self.c & -self.c)  # what o - 4 is still a multiple of
            self.c = 0

    def take(self, name: str, expr: str) -> None:
        """Name ``expr`` (evaluated now) as the value of leaf ``name``'s slots."""
        var = self.var()
        self.emit(1, f"{var} = {expr}")
        for i in self.slots[name]:
            self.values[i] = var

    def align_static(self, size: int) -> None:
        if size <= 1:
            return
        if size <= self.known:
            self.c += (-self.c) % size
            return
        self.flush()
        self.emit(1, f"o += (4 - o) % {size}")
        self.known = size

    def dynamic(self) -> None:
        """After a field of variable size: nothing is known of ``o``'s alignment."""
        self.known = 1

    # -- fields ---------------------------------------------------------------------
    def walk(self, fields: dict[str, str], find: Callable[[str], type[Message]],
             prefix: str) -> None:
        if not fields:  # an empty message has one placeholder byte
            self.c += 1
        for name, spec in fields.items():
            path = prefix + name
            if _nested(spec):
                inner = find(spec)
                self.walk(inner._fields_and_types, inner._lookup, path + ".")
                continue
            m = cdr._TYPE.match(spec)
            if m is None:
                raise cdr.CdrError("?", path, f"unknown field type {spec!r}")
            base, fixed = m["base"], m["fixed"]
            if m["seq"] is None and base in cdr._PRIMITIVES and (
                    fixed is None or int(fixed) > 0):
                code, size = cdr._PRIMITIVES[base]
                count = int(fixed) if fixed is not None else 1
                self.align_static(size)
                if path in self.slots:
                    self.pending.append((self.c, code, count, path))
                    if fixed is not None and base in cdr._BYTES:
                        self.bytes_leaf.add(path)
                self.c += size * count
                continue
            if m["seq"] is None and fixed is None and base.startswith("string"):
                self.string(path)
                continue
            self.flush()
            self.find = find
            if path in self.slots:
                target = self.var()
                self.field(1, name, spec, target)
                elem = m["seq"] or base
                if "/" in elem:  # an array of messages: typed, as from_json gives them
                    cls_name = f"C{self.var()}"
                    self.ns[cls_name] = find(elem)
                    self.emit(1, f"{target} = [{cls_name}.from_json(x) for x in {target}]")
                self.take(path, target)
            else:
                self.skip(m, path)
            self.dynamic()

    def string(self, path: str) -> None:
        """A string: its length (a slot ``#path`` when lengths are asked for), its text
        when asked for, and ``o`` moved past it."""
        self.align_static(4)
        self.flush()
        n = self.var()
        self.emit(1, f"{n} = unpack_from('<I', b, o)[0]")
        self.emit(1, f"if {n} < 1 or o + 4 + {n} > len(b): raise IndexError")
        if path in self.slots:  # the length counts the NUL at the end
            self.take(path, f"str(b[o + 4:o + 3 + {n}], 'utf-8')")
        if "#" + path in self.slots:
            self.take("#" + path, n)
        self.emit(1, f"o += 4 + {n}")
        self.dynamic()

    def skip(self, m: re.Match[str], path: str) -> None:
        """Step over an array not asked for, reading no more than its length."""
        seq, base = m["seq"], m["base"]
        elem = seq or base
        plain = elem in cdr._PRIMITIVES
        if plain and seq is not None:
            size = cdr._PRIMITIVES[elem][1]
            n = self.var()
            self.emit(1, f"o += (4 - o) % 4; {n} = unpack_from('<I', b, o)[0]; o += 4")
            if m["bound"] is not None:
                self.emit(1, f"if {n} > {m['bound']}: raise over_bound({n}, {m['bound']})")
            if size > 1:
                self.emit(1, f"if {n}: o += (4 - o) % {size}")
            self.emit(1, f"if o + {n} * {size} > len(b): "
                         f"raise claims({n}, {size}, len(b) - o)")
            self.emit(1, f"o += {n} * {size}")
            return
        # strings and messages in arrays, wide strings: decoded and dropped
        self.field(1, path, m.string, "_")


_ROWS: weakref.WeakKeyDictionary[type[Message], dict[tuple[str, ...], RowDecoder]] = (
    weakref.WeakKeyDictionary())  # a class a relay released takes its decoders along


def row_decoder(cls: type[Message], wanted: Sequence[str]) -> RowDecoder:
    """The compiled ``row(serialized) -> tuple`` of the leaves ``wanted`` (names from
    :func:`leaf_names`, repeats allowed) of messages of ``cls``; ``#name`` for a string
    ``name`` is its length in the bytes (its NUL included)."""
    mine = _ROWS.setdefault(cls, {})
    found = mine.get(tuple(wanted))
    if found is not None:
        return found
    known = {name for name, _ in leaf_names(cls)}
    missing = [name for name in wanted if name.removeprefix("#") not in known]
    if missing:
        raise cdr.CdrError(cls._type, missing[0], "no such field")
    gen = _RowGen(cls, wanted)
    gen.emit(0, "def row(b):")
    gen.emit(1, "if len(b) < 4 or b[1] != 1: raise ValueError('not little-endian CDR')")
    gen.emit(1, "o = 4")
    gen.walk(cls._fields_and_types, cls._lookup, "")
    gen.flush()
    gen.emit(1, "if o > len(b): raise IndexError")
    gen.emit(1, f"return ({', '.join(gen.values)}{',' if len(gen.values) == 1 else ''})")
    if cdr._charges(gen.lines):  # within the budget
        gen.lines.insert(3, "    r = budget().allowance(len(b))")  # after 'o = 4'
        gen.ns["budget"] = cdr.budget
    exec(compile("\n".join(gen.lines), f"<cdr rows {cls._type}>", "exec"), gen.ns)
    fn: RowDecoder = gen.ns["row"]
    if len(mine) > 64:  # the lists of fields one type was read with: a few
        mine.clear()
    mine[tuple(wanted)] = fn
    return fn


def string_leaves(cls: type[Message]) -> list[str] | None:
    """The string fields of ``cls`` when every other field is a number or a fixed array of
    numbers, so that each field's place is fixed once the strings' lengths are known
    (``sensor_msgs/Imu``: ``header.frame_id``); None for a type with sequences, arrays of
    strings or messages, or wide strings."""
    out: list[str] = []
    for name, spec in leaf_names(cls):
        m = cdr._TYPE.match(spec)
        if m is None or m["seq"] is not None:
            return None
        base, fixed = m["base"], m["fixed"]
        if base in cdr._PRIMITIVES and (fixed is None or int(fixed) > 0):
            continue
        if fixed is not None or not base.startswith("string"):
            return None
        out.append(name)
    return out


def fixed_offsets(cls: type[Message], lengths: Sequence[int]
                  ) -> tuple[dict[str, tuple[int, str, int]], int]:
    """For a type :func:`string_leaves` accepts: each number field's offset in the
    serialized message (its 4-byte header included), struct code and count, given the CDR
    length (its NUL included) of each string in :func:`string_leaves`' order; and where
    the message ends."""
    out: dict[str, tuple[int, str, int]] = {}
    strings = iter(lengths)
    at = 4

    def walk(fields: dict[str, str], find: Callable[[str], type[Message]],
             prefix: str) -> None:
        nonlocal at
        if not fields:  # an empty message has one placeholder byte
            at += 1
        for name, spec in fields.items():
            if _nested(spec):
                inner = find(spec)
                walk(inner._fields_and_types, inner._lookup, f"{prefix}{name}.")
                continue
            m = cdr._TYPE.match(spec)
            assert m is not None  # string_leaves took it
            if m["base"] in cdr._PRIMITIVES:
                code, size = cdr._PRIMITIVES[m["base"]]
                at += (4 - at) % size
                count = int(m["fixed"] or 1)
                out[prefix + name] = (at, code, count)
                at += size * count
            else:
                at += (4 - at) % 4
                at += 4 + next(strings)

    walk(cls._fields_and_types, cls._lookup, "")
    return out, at
