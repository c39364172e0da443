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


def test_html_repr_is_a_table_of_fields() -> None:
    """In Jupyter a message is a table: a row per field, the header nested, the pixels a
    byte count, and text escaped."""
    from html.parser import HTMLParser

    image = Image(width=640, height=480, encoding="<rgb8>", step=1920,
                  data=bytes(640 * 480 * 3))
    image.header.frame_id = "camera"
    page = image._repr_html_()
    assert len(page) < 2000
    assert "<caption style='text-align:left'>sensor_msgs/msg/Image</caption>" in page
    assert "<caption style='text-align:left'>std_msgs/msg/Header</caption>" in page
    assert "<th style='text-align:left'>data</th><td style='text-align:left'>" \
           "<code>&lt;921600 bytes&gt;</code>" in page
    assert "&#x27;&lt;rgb8&gt;&#x27;" in page and "<rgb8>" not in page

    class Tables(HTMLParser):
        opened = 0

        def handle_starttag(self, tag: str, attrs: object) -> None:
            self.opened += tag == "table"

    parser = Tables()
    parser.feed(page)
    assert parser.opened == 3  # the Image, its Header, the Header's stamp
