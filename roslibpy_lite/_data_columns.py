"""One topic of a recording read straight into columns: the fast path of
:func:`roslibpy_lite.data.bag_to_dataframe` (:func:`_bag_columns`), a chunk at a time as
numpy structured arrays for a type of fixed layout but for its strings (:class:`_Layouts`),
else a row per message (:class:`_Rows`); the table is the one the message-by-message path
makes."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ._data_base import _chosen, _numpy, _pandas
from .exceptions import UsageError

if TYPE_CHECKING:
    import pandas


_TIME = ("header.stamp.sec", "header.stamp.nanosec")


def _stamp_leaves(cls: Any) -> tuple[str, ...] | None:
    """The leaves :func:`roslibpy_lite.data._header_stamp_ns` reads from messages of
    ``cls``: none when they have no ``header.stamp``, None when it is of a shape only that
    function should judge."""
    def message(owner: Any, name: str) -> Any:
        spec = owner._fields_and_types.get(name)
        if spec is None or "/" not in spec or "[" in spec or "<" in spec:
            return spec  # absent, or not one nested message: no attributes of its own
        return owner._lookup(spec)

    header = message(cls, "header")
    if not isinstance(header, type):
        return ()
    stamp = message(header, "stamp")
    if stamp is None:
        return ()
    ints = ("int32", "uint32", "int64", "uint64")
    time: dict[str, str] = getattr(stamp, "_fields_and_types", {})
    return _TIME if all(time.get(name.rsplit(".")[-1]) in ints for name in _TIME) else None


def _bag_columns(path: Path, topic: str, chosen: list[str] | None) -> pandas.DataFrame | None:
    """The table of :func:`bag_to_dataframe` read straight into columns, or None when the
    file (or the type) is one to read message by message.

    A type whose fields are numbers, fixed arrays of numbers and strings
    (:func:`msgs.cdr_columns.string_leaves`) is read a chunk at a time as numpy structured
    arrays, one per layout (its length and its strings' lengths place every number); any
    other type one row per message by :func:`msgs.cdr_columns.row_decoder`.
    """
    from msgs.cdr_columns import leaf_names, string_leaves

    from .bag._records import _message_class
    from .bag.reader import topic_chunks

    found = topic_chunks(path, topic)
    if found is None:
        return None
    try:
        cls = _message_class(found.type_name, found.definition)
    except Exception:
        return None
    leaves = dict(leaf_names(cls))
    try:
        names = list(leaves) if chosen is None else _chosen(leaves, chosen)
    except UsageError:  # said by the general path, at the first message (if there is one)
        return None
    stamp = _stamp_leaves(cls)
    if not names or stamp is None:
        return None
    strings = string_leaves(cls)
    reader = _Rows(cls, [*names, *stamp]) if strings is None else _Layouts(cls, [*names, *stamp],
                                                                         strings)
    times: list[int] = []
    for batch in found.batches:
        try:
            reader.add(batch)
        except Exception:
            error = _undecodable(cls, batch, path, topic, len(times))
            if error is None:  # each message decodes: the general path reads them
                return None
            raise error from None
        times.extend([t for t, _ in batch])
    if not times:
        return None
    np = _numpy()
    columns = reader.columns()
    if any(a > b for a, b in itertools.pairwise(times)):  # stable, as mcap orders
        order = np.argsort(np.array(times, np.int64), kind="stable")
        times = [times[i] for i in order]
        columns = [[col[i] for i in order] if isinstance(col, list) else col[order]
                   for col in columns]
    if stamp:
        secs, nanos = columns[-2:]
        index = np.asarray(secs, np.int64) * 1_000_000_000 + np.asarray(nanos, np.int64)
    else:
        index = np.array(times, np.int64)
    pd = _pandas()
    frame = pd.DataFrame({name: col for name, col in zip(names, columns, strict=False)})
    frame.index = pd.to_datetime(index, unit="ns", utc=True).rename("time")
    return frame


class _Rows:
    """Columns gathered a row per message (any type)."""

    def __init__(self, cls: Any, wanted: list[str]) -> None:
        from msgs.cdr_columns import row_decoder

        self.row = row_decoder(cls, wanted)
        self.rows: list[tuple[Any, ...]] = []

    def add(self, batch: list[tuple[int, Any]]) -> None:
        row = self.row
        self.rows.extend([row(data) for _, data in batch])

    def columns(self) -> list[Any]:
        return [list(col) for col in zip(*self.rows, strict=True)]


_NUMPY_CODES = {"?": "u1", "B": "u1", "b": "i1", "h": "<i2", "H": "<u2", "i": "<i4",
                "I": "<u4", "q": "<i8", "Q": "<u8", "f": "<f4", "d": "<f8"}


class _Layouts:
    """Columns of a type of fixed layout but for its strings, read a chunk at a time: the
    messages of one layout (length and strings' lengths) as one numpy structured array."""

    def __init__(self, cls: Any, wanted: list[str], strings: list[str]) -> None:
        from msgs.cdr_columns import leaf_names, row_decoder

        self.cls, self.wanted = cls, wanted
        self.texts = [name for name in wanted if name in strings]
        self.numbers = [name for name in dict.fromkeys(wanted) if name not in strings]
        # per message: the strings asked for, then every string's length (the layout)
        self.row = row_decoder(cls, [*self.texts, *(f"#{name}" for name in strings)])
        self.dtypes: dict[tuple[int, ...], Any] = {}
        self.parts: dict[str, list[Any]] = {name: [] for name in (*self.texts, *self.numbers)}
        self.kinds: dict[str, tuple[str, int]] = {}
        self.bytes = {name for name, spec in leaf_names(cls)  # uint8[n], char[n]: bytes
                      if spec.split("[")[0] in ("uint8", "char") and "[" in spec}

    def dtype(self, key: tuple[int, ...]) -> Any:
        """The structured dtype of the numbers asked for in messages of layout ``key``."""
        found = self.dtypes.get(key)
        if found is None:
            from msgs.cdr_columns import fixed_offsets

            np = _numpy()
            offsets, _ = fixed_offsets(self.cls, key[1:])
            formats = []
            for name in self.numbers:
                _, code, count = offsets[name]
                self.kinds[name] = (code, count)
                one = _NUMPY_CODES[code]
                formats.append(one if count == 1 else (one, (count,)))
            found = self.dtypes[key] = np.dtype({
                "names": self.numbers, "formats": formats, "itemsize": key[0],
                "offsets": [offsets[name][0] for name in self.numbers]})
        return found

    def add(self, batch: list[tuple[int, Any]]) -> None:
        np = _numpy()
        row = self.row
        values = [row(data) for _, data in batch]
        texts = len(self.texts)
        for i, name in enumerate(self.texts):
            self.parts[name].append([v[i] for v in values])
        if not self.numbers:
            return
        keys = [(len(data), *v[texts:]) for v, (_, data) in zip(values, batch, strict=True)]
        if not keys:  # a chunk without an index of its messages may hold none of the topic
            return
        if keys.count(keys[0]) == len(keys):  # the usual case: one layout in the chunk
            arr = np.frombuffer(b"".join([data for _, data in batch]), self.dtype(keys[0]))
            for name in self.numbers:
                self.parts[name].append(arr[name])
            return
        layouts: dict[tuple[int, ...], list[int]] = {}
        for i, key in enumerate(keys):
            layouts.setdefault(key, []).append(i)
        chunk = {name: None for name in self.numbers}
        for key, where in layouts.items():
            arr = np.frombuffer(b"".join([batch[i][1] for i in where]), self.dtype(key))
            for name in self.numbers:
                part, col = arr[name], chunk[name]
                if col is None:
                    col = chunk[name] = np.empty((len(batch), *part.shape[1:]), part.dtype)
                col[where] = part
        for name in self.numbers:
            self.parts[name].append(chunk[name])

    def columns(self) -> list[Any]:
        np = _numpy()
        out: dict[str, Any] = {}
        for name, parts in self.parts.items():
            if name in self.kinds:
                out[name] = _as_python_would(np.concatenate(parts), *self.kinds[name],
                                             name in self.bytes)
            elif name in self.texts:
                out[name] = [text for part in parts for text in part]
        return [out[name] for name in self.wanted]


def _as_python_would(col: Any, code: str, count: int, as_bytes: bool) -> Any:
    """A column of numbers as the row-by-row table holds them: scalars as int64, float64
    or bool arrays (a uint64 past int64 as Python ints), arrays as lists (bytes for
    ``uint8``/``char``)."""
    np = _numpy()
    if count > 1:
        if as_bytes:
            return [cell.tobytes() for cell in col]
        return (col != 0).tolist() if code == "?" else col.tolist()
    if code == "?":
        return col != 0
    if code in "fd":
        return col.astype(np.float64)
    if code == "Q" and len(col) and col.max() >= 2**63:
        return col.tolist()
    return col.astype(np.int64)


def _undecodable(cls: Any, batch: list[tuple[int, Any]], path: Path, topic: str,
                 done: int) -> Exception | None:
    """The error of the first message of ``batch`` that does not decode (None: they all do)."""
    from msgs.cdr import CdrError, decode

    for i, (_, data) in enumerate(batch):
        try:
            cls.from_json(decode(data, cls))
        except CdrError as exc:
            return CdrError(exc.type_name, exc.path, exc.why,
                            where=f"{path}: message {done + i} on {topic}")
    return None
