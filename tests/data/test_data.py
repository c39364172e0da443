"""roslibpy_lite.data: images, compressed images and point clouds as numpy arrays, messages
as tables; unit cases here, the real bridge and files in test_data_bridge.py."""

from __future__ import annotations

import base64
import datetime
import io
import struct

import numpy as np
import pandas as pd
import pytest

from msgs.geometry_msgs.msg import Vector3
from msgs.sensor_msgs.msg import CompressedImage, Imu, PointCloud2, PointField
from roslibpy_lite import UsageError
from roslibpy_lite.data import (
    IMAGE_ENCODINGS,
    flatten,
    from_numpy,
    stamp_datetime,
    stamp_seconds,
    to_dataframe,
    to_numpy,
)

RNG = np.random.default_rng(7)


def _pixels(encoding: str, h: int = 5, w: int = 7) -> np.ndarray:
    code, channels = IMAGE_ENCODINGS[encoding]
    dtype = np.dtype(code)
    shape = (h, w) if channels == 1 else (h, w, channels)
    if dtype.kind == "f":
        return RNG.standard_normal(shape).astype(dtype)
    info = np.iinfo(dtype)
    return RNG.integers(info.min, info.max, size=shape, endpoint=True, dtype=dtype)


@pytest.mark.parametrize("encoding", sorted(IMAGE_ENCODINGS))
def test_every_encoding_round_trips_typed_and_as_dicts(encoding: str) -> None:
    """from_numpy then to_numpy gives the pixels back, for a typed Image and for its dict
    forms: bytes (CBOR) and base64 text (JSON)."""
    pixels = _pixels(encoding)
    msg = from_numpy(pixels, encoding, frame_id="cam")
    assert (msg.height, msg.width, msg.encoding, msg.header.frame_id) == (5, 7, encoding, "cam")
    assert msg.step * msg.height == len(msg.data) == pixels.nbytes
    as_json = msg.to_json()
    assert isinstance(as_json["data"], str)  # what a JSON subscription gives
    as_cbor = {**as_json, "data": bytes(msg.data)}
    for form in (msg, as_json, as_cbor):
        got = to_numpy(form)
        assert got.shape == pixels.shape and got.dtype == pixels.dtype
        np.testing.assert_array_equal(got, pixels)


def test_rows_with_padding_and_big_endian_pixels() -> None:
    """A step longer than the row (padding) is cut off; big-endian 16-bit pixels read right."""
    pixels = np.arange(12, dtype=">u2").reshape(3, 4)
    padded = b"".join(row.tobytes() + b"\xee" * 6 for row in pixels)
    msg = {"height": 3, "width": 4, "encoding": "mono16", "is_bigendian": 1, "step": 14,
           "data": base64.b64encode(padded).decode()}
    got = to_numpy(msg)
    np.testing.assert_array_equal(got, pixels)
    assert got.dtype.byteorder == ">"
    # and a little-endian one given as a list of ints
    little = {**msg, "is_bigendian": 0, "step": 8,
              "data": list(pixels.astype("<u2").tobytes())}
    np.testing.assert_array_equal(to_numpy(little), pixels)


def test_default_encodings_by_shape_and_dtype() -> None:
    """from_numpy names the encoding from the array when none is given."""
    cases = {(np.uint8, (2, 2)): "mono8", (np.uint16, (2, 2)): "mono16",
             (np.uint8, (2, 2, 3)): "rgb8", (np.uint8, (2, 2, 4)): "rgba8",
             (np.float32, (2, 2)): "32FC1", (np.int16, (2, 2, 2)): "16SC2"}
    for (dtype, shape), encoding in cases.items():
        assert from_numpy(np.zeros(shape, dtype)).encoding == encoding


def test_bad_images_say_what_is_wrong() -> None:
    """An unknown encoding, too few bytes, a shape or dtype that does not fit: one clear line."""
    ok = from_numpy(np.zeros((2, 3, 3), np.uint8)).to_json()
    with pytest.raises(UsageError, match="'yuv422_yuy2' is not one to_numpy knows"):
        to_numpy({**ok, "encoding": "yuv422_yuy2"})
    with pytest.raises(UsageError, match=r"a 3x2 rgb8 image needs rows of 9 bytes .* data 17"):
        to_numpy({**ok, "data": base64.b64encode(bytes(17)).decode()})
    with pytest.raises(UsageError, match=r"Image\.data: not base64"):
        to_numpy({**ok, "data": "!!!"})
    with pytest.raises(UsageError, match="rgb8 is 3 channel"):
        from_numpy(np.zeros((2, 2), np.uint8), "rgb8")
    with pytest.raises(UsageError, match="shape"):
        from_numpy(np.zeros(4, np.uint8))
    with pytest.raises(UsageError, match="Image, CompressedImage or PointCloud2"):
        to_numpy({"data": "x"})


def test_compressed_images_decode_with_pillow() -> None:
    """A PNG CompressedImage (bytes or base64) decodes to its pixels."""
    from PIL import Image

    pixels = _pixels("rgb8", 6, 9)
    buf = io.BytesIO()
    Image.fromarray(pixels).save(buf, format="PNG")
    typed = CompressedImage(format="png", data=buf.getvalue())
    np.testing.assert_array_equal(to_numpy(typed), pixels)
    np.testing.assert_array_equal(to_numpy(typed.to_json()), pixels)
    with pytest.raises(UsageError, match="CompressedImage \\('png'\\)"):
        to_numpy(CompressedImage(format="png", data=b"not a png"))


def _cloud(big: bool = False, pad: int = 0) -> tuple[PointCloud2, np.ndarray]:
    """A 2x3 cloud: x, y, z float32, intensity uint16 at offset 16, rgb float64 x2 at 20."""
    order = ">" if big else "<"
    fields = [PointField(name="x", offset=0, datatype=7, count=1),
              PointField(name="y", offset=4, datatype=7, count=1),
              PointField(name="z", offset=8, datatype=7, count=1),
              PointField(name="intensity", offset=16, datatype=4, count=1),
              PointField(name="pair", offset=20, datatype=8, count=2)]
    point_step = 40
    rows = []
    want = []
    for r in range(2):
        row = b""
        for c in range(3):
            x, y, z, i = float(r), float(c), r * 10.0 + c, 100 * r + c
            pair = (r + 0.5, c - 0.25)
            point = bytearray(point_step)
            struct.pack_into(order + "fff", point, 0, x, y, z)
            struct.pack_into(order + "H", point, 16, i)
            struct.pack_into(order + "dd", point, 20, *pair)
            row += bytes(point)
            want.append((x, y, z, i, pair))
        rows.append(row + b"\x00" * pad)
    msg = PointCloud2(height=2, width=3, fields=fields, is_bigendian=big, point_step=point_step,
                      row_step=3 * point_step + pad, data=b"".join(rows), is_dense=True)
    return msg, np.array(want, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"),
                                       ("intensity", "u2"), ("pair", "f8", (2,))])


@pytest.mark.parametrize(("big", "pad"), [(False, 0), (True, 0), (False, 8)])
def test_point_clouds_are_structured_arrays(big: bool, pad: int) -> None:
    """Every PointField is a field of the record (offsets, counts, byte order, row padding),
    typed or as the dict a JSON subscription gives."""
    msg, want = _cloud(big, pad)
    for form in (msg, msg.to_json()):
        got = to_numpy(form)
        assert got.shape == (6,)
        assert want.dtype.names is not None
        for name in want.dtype.names:
            np.testing.assert_array_equal(got[name], want[name])
    bad = msg.to_json()
    bad["fields"][0]["datatype"] = 9
    with pytest.raises(UsageError, match="PointField 'x': datatype 9"):
        to_numpy(bad)


def _imu(i: int, sec: int | None = 100) -> Imu:
    imu = Imu(angular_velocity=Vector3(x=float(i), y=2.0 * i, z=-1.0))
    if sec is not None:
        imu.header.stamp.sec, imu.header.stamp.nanosec = sec + i, 250_000_000
    return imu


def test_flatten_names_nested_fields_with_dots() -> None:
    """Nested fields are dotted columns; asked fields come in order, a message name brings its
    fields; an unknown name is refused naming what there is."""
    flat = flatten(_imu(1))
    assert flat["angular_velocity.y"] == 2.0 and flat["header.stamp.sec"] == 101
    assert len(flat["orientation_covariance"]) == 9
    assert flatten(_imu(1).to_json(), ["angular_velocity"]) == {
        "angular_velocity.x": 1.0, "angular_velocity.y": 2.0, "angular_velocity.z": -1.0}
    with pytest.raises(UsageError, match=r"no field 'angular_velocity\.w'"):
        flatten(_imu(1), ["angular_velocity.w"])


def test_to_dataframe_indexes_by_header_stamp_else_the_times_given() -> None:
    """Header stamps make a UTC time index; without headers the given times do; else 0..n."""
    frame = to_dataframe([_imu(i) for i in range(3)], ["angular_velocity.x"])
    assert list(frame.columns) == ["angular_velocity.x"]
    assert list(frame["angular_velocity.x"]) == [0.0, 1.0, 2.0]
    assert frame.index.name == "time"
    assert frame.index[1] == pd.Timestamp(101.25, unit="s", tz="UTC")
    plain = [{"data": i} for i in range(3)]
    timed = to_dataframe(plain, times=[5.0, 6.0, 7.5])
    assert timed.index[2] == pd.Timestamp(7.5, unit="s", tz="UTC")
    assert list(to_dataframe(plain).index) == [0, 1, 2]
    with pytest.raises(UsageError, match="2 times for 3 messages"):
        to_dataframe(plain, times=[1.0, 2.0])


def test_messages_with_and_without_a_header_are_indexed_by_the_times_given() -> None:
    """When only some messages have a header stamp, the index is the given times, all of
    them (not the stamps with gaps); without times it is 0..n."""
    mixed = [_imu(0), {"angular_velocity": {"x": 5.0}}, _imu(2).to_json()]
    frame = to_dataframe(mixed, ["angular_velocity.x"], times=[5.0, 6.0, 7.5])
    assert list(frame.index) == [pd.Timestamp(t, unit="s", tz="UTC") for t in (5.0, 6.0, 7.5)]
    assert frame.index.name == "time"
    assert list(frame["angular_velocity.x"]) == [0.0, 5.0, 2.0]
    assert list(to_dataframe(mixed, ["angular_velocity.x"]).index) == [0, 1, 2]


def test_stamps_as_seconds_and_datetimes() -> None:
    """A Time (typed, dict, or ROS 1's secs/nsecs) as seconds and as a UTC datetime."""
    stamp = _imu(0, 1_700_000_000).header.stamp
    assert stamp_seconds(stamp) == pytest.approx(1_700_000_000.25)
    assert stamp_seconds({"secs": 3, "nsecs": 500_000_000}) == 3.5
    when = stamp_datetime(stamp.to_json())
    assert when == datetime.datetime(2023, 11, 14, 22, 13, 20, 250000, tzinfo=datetime.UTC)
    with pytest.raises(UsageError, match="sec and nanosec"):
        stamp_seconds({"seconds": 1})


def test_an_empty_table_keeps_the_columns_asked_for() -> None:
    """No message (a collect() on a silent topic) gives an empty table with the columns asked
    for, indexed by time, so a column lookup finds an empty column."""
    from roslibpy_lite.handles import Collected

    frame = to_dataframe(Collected([], []), ["linear_acceleration.z"])
    assert list(frame.columns) == ["linear_acceleration.z"] and len(frame) == 0
    assert frame["linear_acceleration.z"].empty and frame.index.name == "time"
