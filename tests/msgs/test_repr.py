"""repr() of messages stays short for large fields, and unchanged for small ones."""

from __future__ import annotations

from msgs.sensor_msgs.msg import Image
from msgs.std_msgs.msg import Float32MultiArray, String


def test_image_repr_summarises_its_pixels() -> None:
    """A 640x480 rgb8 Image prints its data as a byte count, not 3.6 MB of text."""
    image = Image(width=640, height=480, encoding="rgb8", step=1920, data=bytes(640 * 480 * 3))
    text = repr(image)
    assert "data=<921600 bytes>" in text
    assert "width=640" in text and "encoding='rgb8'" in text
    assert len(text) < 300


def test_long_lists_and_texts_are_summarised_short_ones_kept() -> None:
    """Long lists show a head and a count, long texts a prefix and a count; small values as is."""
    assert repr(String(data="hi")) == "String(data='hi')"
    many = repr(Float32MultiArray(data=[1.5] * 1000))
    assert "data=[1.5, 1.5, 1.5, ... <1000 items>]" in many
    assert "<5000 chars>" in repr(String(data="x" * 5000))
    assert repr(Float32MultiArray(data=[1.0, 2.0])).endswith("data=[1.0, 2.0])")
