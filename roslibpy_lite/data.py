"""Robot data as arrays and tables: numpy images and point clouds, pandas DataFrames.

Needs the ``data`` extra (``pip install 'roslibpy-lite[data]'``: numpy and pandas, Pillow
for ``CompressedImage``); the rest of the client does not. Every function takes a message
as a subscription gives it, whatever its compression: a dict (JSON, CBOR) or a typed
message from :mod:`msgs`, and a ``uint8[]`` field as ``bytes`` or as the base64 text a
JSON subscription carries.

- :func:`to_numpy`: a ``sensor_msgs/Image`` (rgb8, bgr8, rgba8, bgra8, mono8, mono16 and
  the ``8UC1`` ... ``64FC1`` family) as an ``(height, width[, channels])`` array, a
  ``CompressedImage`` decoded with Pillow, a ``PointCloud2`` as a structured array
  (one record per point, a field per ``PointField``).
- :func:`from_numpy`: an array as a typed ``sensor_msgs/Image``, ready to publish.
- :func:`flatten`: one message as a flat dict, nested fields as dotted names
  (``linear_acceleration.x``).
- :func:`to_dataframe`: messages as a DataFrame, one row each, indexed by their header
  stamps (or the times given); :func:`bag_to_dataframe` does the same for a topic of an
  MCAP file.
- :func:`stamp_seconds`, :func:`stamp_datetime`: a ``builtin_interfaces/Time``.

Models: rosbags' ``get_dataframe`` and ``message_to_cvimage``, cv_bridge, and
``sensor_msgs_py.point_cloud2.read_points``.
"""

from __future__ import annotations

import base64
import datetime
import io
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ._data_base import _chosen, _numpy, _pandas
from ._data_columns import _bag_columns as _bag_columns  # tests call and patch it here
from .exceptions import UsageError
from .messages import name_hint

if TYPE_CHECKING:
    import numpy
    import pandas

__all__ = [
    "IMAGE_ENCODINGS",
    "MAX_PIXELS",
    "bag_to_dataframe",
    "flatten",
    "from_numpy",
    "stamp_datetime",
    "stamp_seconds",
    "to_dataframe",
    "to_numpy",
]

IMAGE_ENCODINGS: dict[str, tuple[str, int]] = {
    "rgb8": ("u1", 3), "bgr8": ("u1", 3), "rgba8": ("u1", 4), "bgra8": ("u1", 4),
    "rgb16": ("u2", 3), "bgr16": ("u2", 3), "rgba16": ("u2", 4), "bgra16": ("u2", 4),
    "mono8": ("u1", 1), "mono16": ("u2", 1),
    **{f"{bits}{kind}C{n}": (f"{'u' if kind == 'U' else 'i' if kind == 'S' else 'f'}"
                             f"{bits // 8}", n)
       for bits, kind in ((8, "U"), (8, "S"), (16, "U"), (16, "S"), (32, "S"), (32, "F"),
                          (64, "F"))
       for n in (1, 2, 3, 4)},
}
"""``sensor_msgs/Image`` encodings :func:`to_numpy` and :func:`from_numpy` know: numpy
dtype code and channels (bayer patterns are single-channel 8 or 16 bit, read as such)."""

MAX_PIXELS = 50_000_000
"""The most pixels (width x height) a ``CompressedImage`` may declare for :func:`to_numpy` to
decode it: its header is read first, so a small file declaring a huge image (a decompression
bomb: a 165 KB PNG of 13000x13000) is refused before any pixel is. ``max_pixels`` changes it."""

_POINT_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
"""``sensor_msgs/PointField`` datatype -> numpy dtype code."""


def _field(msg: Any, name: str) -> Any:
    if isinstance(msg, Mapping):
        try:
            return msg[name]
        except KeyError:
            raise UsageError(f"the message has no field {name!r} "
                             f"(it has {', '.join(map(str, msg)) or 'none'})") from None
    try:
        return getattr(msg, name)
    except AttributeError:
        raise UsageError(f"{type(msg).__name__} has no field {name!r}") from None


def _has(msg: Any, *names: str) -> bool:
    if isinstance(msg, Mapping):
        return all(name in msg for name in names)
    return all(hasattr(msg, name) for name in names)


def _bytes(value: Any, what: str) -> bytes | bytearray | memoryview:
    """A ``uint8[]`` field's bytes, however the subscription gave it."""
    if isinstance(value, bytes | bytearray | memoryview):
        return value
    if isinstance(value, str):  # a JSON subscription's base64
        try:
            return base64.b64decode(value, validate=True)
        except ValueError as exc:
            raise UsageError(f"{what}: not base64 ({exc})") from None
    if isinstance(value, Sequence):
        return bytes(value)
    raise UsageError(f"{what}: expected bytes, base64 text or a list of ints, "
                     f"got {type(value).__name__}")


def to_numpy(msg: Any, *, max_pixels: int = MAX_PIXELS) -> numpy.ndarray[Any, Any]:
    """The pixels of an ``Image`` or ``CompressedImage``, or the points of a ``PointCloud2``.

    An image is ``(height, width)`` for one channel and ``(height, width, channels)`` for
    more, in the message's own order (``bgr8`` stays BGR), rows without their padding; a
    compressed image is decoded by Pillow (RGB for colour); a point cloud is a structured
    array, one record per point, one field per ``PointField`` (a count above one is a
    sub-array). The array is a view of the message's bytes where it can be (read only).

    Raises:
        UsageError: not one of those types, an encoding it does not know, a size that
            does not match, a compressed image over ``max_pixels`` (:data:`MAX_PIXELS`),
            or numpy (Pillow) missing.
    """
    if _has(msg, "fields", "point_step", "row_step"):
        return _cloud(msg)
    if _has(msg, "encoding", "step", "height", "width"):
        return _image(msg)
    if _has(msg, "format", "data"):
        return _compressed(msg, max_pixels)
    raise UsageError("to_numpy takes a sensor_msgs Image, CompressedImage or PointCloud2")


def _image(msg: Any) -> numpy.ndarray[Any, Any]:
    np = _numpy()
    encoding = str(_field(msg, "encoding"))
    known = IMAGE_ENCODINGS.get(encoding)
    if known is None and encoding.startswith("bayer_"):
        known = ("u2" if encoding.endswith("16") else "u1", 1)
    if known is None:
        raise UsageError(f"image encoding {encoding!r} is not one to_numpy knows "
                         f"({', '.join(sorted(IMAGE_ENCODINGS))}, bayer_*)")
    code, channels = known
    height, width, step = (int(_field(msg, k)) for k in ("height", "width", "step"))
    dtype = np.dtype(code).newbyteorder(">" if _field(msg, "is_bigendian") else "<")
    row = width * channels * dtype.itemsize
    data = _bytes(_field(msg, "data"), "Image.data")
    if step < row or len(data) < step * height:
        raise UsageError(f"a {width}x{height} {encoding} image needs rows of {row} bytes "
                         f"({height} of them): step is {step}, data {len(data)} bytes")
    rows = np.frombuffer(data, np.uint8, count=step * height).reshape(height, step)
    pixels = rows[:, :row]
    if step != row:
        pixels = np.ascontiguousarray(pixels)
    shape = (height, width) if channels == 1 else (height, width, channels)
    return pixels.view(dtype).reshape(shape)  # type: ignore[no-any-return]


def _compressed(msg: Any, max_pixels: int) -> numpy.ndarray[Any, Any]:
    np = _numpy()
    try:
        from PIL import Image
    except ImportError:
        raise UsageError("a CompressedImage needs Pillow: pip install 'roslibpy-lite[data]'"
                         ) from None
    data = _bytes(_field(msg, "data"), "CompressedImage.data")
    what = f"CompressedImage ({_field(msg, 'format')!r})"
    try:
        with Image.open(io.BytesIO(data)) as img:  # lazy: the header only, so far
            width, height = img.size
            if width * height > max_pixels:
                raise UsageError(f"{what}: {width}x{height} is {width * height:,} pixels, over "
                                 f"the bound of {max_pixels:,} (max_pixels); not decoded")
            plain = img if img.mode in ("L", "I;16", "RGB", "RGBA") else img.convert("RGB")
            return np.asarray(plain)  # type: ignore[no-any-return]
    except (OSError, Image.DecompressionBombError) as exc:
        raise UsageError(f"{what}: {exc}") from None


def _cloud(msg: Any) -> numpy.ndarray[Any, Any]:
    np = _numpy()
    order = ">" if _field(msg, "is_bigendian") else "<"
    names, formats, offsets = [], [], []
    for f in _field(msg, "fields"):
        code = _POINT_TYPES.get(int(_field(f, "datatype")))
        name = str(_field(f, "name"))
        if code is None:
            raise UsageError(f"PointField {name!r}: datatype {_field(f, 'datatype')} is not "
                             "one of 1-8 (INT8 ... FLOAT64)")
        count = int(_field(f, "count"))
        names.append(name)
        formats.append((order + code, (count,)) if count > 1 else order + code)
        offsets.append(int(_field(f, "offset")))
    point_step, row_step = int(_field(msg, "point_step")), int(_field(msg, "row_step"))
    height, width = int(_field(msg, "height")), int(_field(msg, "width"))
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets,
                      "itemsize": point_step})
    data = _bytes(_field(msg, "data"), "PointCloud2.data")
    if row_step < width * point_step or len(data) < row_step * height:
        raise UsageError(f"a {width}x{height} cloud of {point_step}-byte points needs rows of "
                         f"{width * point_step} bytes: row_step is {row_step}, data "
                         f"{len(data)} bytes")
    rows = np.frombuffer(data, np.uint8, count=row_step * height).reshape(height, row_step)
    points = np.ascontiguousarray(rows[:, :width * point_step]).view(dtype)
    return points.reshape(height * width)  # type: ignore[no-any-return]


def from_numpy(array: Any, encoding: str | None = None, *, frame_id: str = "",
               stamp: Any = None) -> Any:
    """A ``sensor_msgs/msg/Image`` (typed, from :mod:`msgs`) holding ``array``'s pixels.

    ``encoding`` defaults by shape and dtype: ``mono8``/``mono16`` for 2-D uint8/uint16,
    ``rgb8``/``rgba8`` for 3 or 4 uint8 channels, ``32FC1`` for 2-D float32, else the
    ``{bits}{U,S,F}C{n}`` name. ``stamp``: a ``Time`` (typed or dict) for the header.
    """
    np = _numpy()
    from msgs.builtin_interfaces.msg import Time
    from msgs.sensor_msgs.msg import Image
    from msgs.std_msgs.msg import Header

    arr = np.asarray(array)
    if arr.ndim not in (2, 3):
        raise UsageError(f"from_numpy takes (height, width[, channels]) pixels, got shape "
                         f"{arr.shape}")
    channels = 1 if arr.ndim == 2 else arr.shape[2]
    if encoding is None:
        encoding = _default_encoding(arr.dtype, channels)
    known = IMAGE_ENCODINGS.get(encoding)
    if known is None:
        raise UsageError(f"image encoding {encoding!r} is not one from_numpy knows")
    code, want = known
    if want != channels or np.dtype(code).kind != arr.dtype.kind \
            or np.dtype(code).itemsize != arr.dtype.itemsize:
        raise UsageError(f"{encoding} is {want} channel(s) of {np.dtype(code)}, the array has "
                         f"{channels} of {arr.dtype}")
    big = arr.dtype.byteorder == ">"
    data = np.ascontiguousarray(arr).tobytes()
    height, width = arr.shape[:2]
    if stamp is None:
        time = Time()
    elif isinstance(stamp, Time):
        time = stamp
    else:
        time = Time(sec=int(_field(stamp, "sec")), nanosec=int(_field(stamp, "nanosec")))
    return Image(header=Header(stamp=time, frame_id=frame_id), height=height, width=width,
                 encoding=encoding, is_bigendian=int(big), step=len(data) // max(height, 1),
                 data=data)


def _default_encoding(dtype: Any, channels: int) -> str:
    if dtype.kind == "u" and dtype.itemsize == 1:
        return {1: "mono8", 3: "rgb8", 4: "rgba8"}.get(channels, f"8UC{channels}")
    if dtype.kind == "u" and dtype.itemsize == 2 and channels == 1:
        return "mono16"
    kind = {"u": "U", "i": "S", "f": "F"}.get(dtype.kind)
    if kind is None:
        raise UsageError(f"no image encoding holds {dtype} pixels")
    return f"{dtype.itemsize * 8}{kind}C{channels}"


def stamp_seconds(stamp: Any) -> float:
    """A ``builtin_interfaces/Time`` (typed, or a dict; ``secs``/``nsecs`` too) in seconds."""
    if _has(stamp, "sec", "nanosec"):
        return int(_field(stamp, "sec")) + int(_field(stamp, "nanosec")) * 1e-9
    if _has(stamp, "secs", "nsecs"):
        return int(_field(stamp, "secs")) + int(_field(stamp, "nsecs")) * 1e-9
    raise UsageError("a stamp has sec and nanosec")


def stamp_datetime(stamp: Any) -> datetime.datetime:
    """A ``builtin_interfaces/Time`` as an aware UTC ``datetime`` (microseconds kept)."""
    return datetime.datetime.fromtimestamp(stamp_seconds(stamp), datetime.UTC)


def flatten(msg: Any, fields: Iterable[str] | None = None) -> dict[str, Any]:
    """One message as a flat dict: nested fields under dotted names (``header.stamp.sec``),
    arrays and byte strings as one value each. ``fields``: only these (dotted) names, in
    this order; a name that is a nested message brings all of its fields."""
    flat: dict[str, Any] = {}
    _flatten_into(flat, "", msg)
    if fields is None:
        return flat
    return {name: flat[name] for name in _chosen(flat, fields)}




def _flatten_into(out: dict[str, Any], prefix: str, value: Any) -> None:
    if isinstance(value, Mapping):
        items: Iterable[tuple[str, Any]] = value.items()
    elif hasattr(value, "get_fields_and_field_types"):
        items = ((name, getattr(value, name)) for name in value.get_fields_and_field_types())
    else:
        out[prefix] = value
        return
    for name, inner in items:
        _flatten_into(out, f"{prefix}{name}" if not prefix else f"{prefix}.{name}", inner)


def to_dataframe(messages: Iterable[Any], fields: Iterable[str] | None = None, *,
                 times: Iterable[float] | None = None) -> pandas.DataFrame:
    """Messages as a DataFrame, one row each, columns as :func:`flatten` names them.

    The index is the messages' ``header.stamp`` (UTC ``DatetimeIndex``, named ``time``)
    when every message has one; else ``times`` (seconds since the epoch, one per message,
    e.g. when they were received) when given, or the receive times of what
    ``sub.collect(seconds)`` returned; else 0, 1, 2, ...
    """
    if times is None:
        times = getattr(messages, "times", None)  # a Collected list
    times_ns = None if times is None else [round(t * 1e9) for t in times]
    chosen = list(fields) if fields is not None else None
    msgs = list(messages)
    frame = _frame([flatten(m, chosen) for m in msgs], [_header_stamp_ns(m) for m in msgs],
                   times_ns)
    if not msgs and chosen:  # no message (a silent topic): still the columns asked for
        frame = frame.reindex(columns=chosen)
    return frame


def _frame(rows: list[dict[str, Any]], stamps: list[int | None],
           times_ns: list[int] | None) -> pandas.DataFrame:
    """The table of ``rows``, indexed by ``stamps`` when every row has one, else ``times_ns``."""
    pd = _pandas()
    frame = pd.DataFrame(rows)
    index: list[int | None] | None = stamps
    if not rows or any(t is None for t in stamps):
        index = list(times_ns) if times_ns is not None else None
        if index is not None and len(index) != len(rows):
            raise UsageError(f"{len(index)} times for {len(rows)} messages")
    if index is not None:
        frame.index = pd.to_datetime(index, unit="ns", utc=True).rename("time")
    return frame


def _header_stamp_ns(msg: Any) -> int | None:
    if not _has(msg, "header"):
        return None
    header = _field(msg, "header")
    if not _has(header, "stamp"):
        return None
    stamp = _field(header, "stamp")
    return int(_field(stamp, "sec")) * 1_000_000_000 + int(_field(stamp, "nanosec"))


def bag_to_dataframe(path: str | Path, topic: str,
                     fields: Iterable[str] | None = None) -> pandas.DataFrame:
    """One topic of an MCAP file (ours, rosbag2's) or of a rosbag2 recording (its directory
    or a bare ``.db3`` file; the rosbag2 extra) as a DataFrame (see :func:`to_dataframe`;
    a message without a header stamp is indexed by when it was recorded).

    Only the fields asked for are read, straight from each message's CDR bytes into
    columns (:mod:`msgs.cdr_columns`), when the file has its chunk index (a recording cut
    short is read message by message instead; the table is the same).

    Raises:
        UsageError: no message on ``topic`` (the error names the file's topics), no field
            of that name, or a chunk of the file that does not read.
        msgs.cdr.CdrError: a message that does not decode; the error names the topic,
            the message's place among the topic's messages and the field.
    """
    from .bag import info, read
    from .bag._rosbag2 import need_reader

    need_reader(path)
    path = Path(path)
    chosen = list(fields) if fields is not None else None
    frame = _bag_columns(path, topic, chosen)
    if frame is not None:
        return frame
    rows: list[dict[str, Any]] = []
    stamps: list[int | None] = []
    times_ns: list[int] = []
    for i, rec in enumerate(read(path, topics=[topic])):  # one at a time: only rows stay
        msg = _decode_named(rec.decode, path, topic, i)
        rows.append(flatten(msg, chosen))
        stamps.append(_header_stamp_ns(msg))
        times_ns.append(rec.log_time_ns)
    if not rows:
        in_file = [t.topic for t in info(path).topics]
        where = "" if topic in in_file else f"; {name_hint(topic, in_file)}"
        raise UsageError(f"{path}: no message on {topic}{where}")
    return _frame(rows, stamps, times_ns)


def _decode_named(decode: Callable[[], Any], path: Path, topic: str, index: int) -> Any:
    """``decode()``, its CdrError naming the file, the topic and the message's place."""
    from msgs.cdr import CdrError

    try:
        return decode()
    except CdrError as exc:
        raise CdrError(exc.type_name, exc.path, exc.why,
                       where=f"{path}: message {index} on {topic}") from None
