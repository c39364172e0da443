"""What a message looks like to an agent where its numbers say more than its bytes: an
image as an image (scaled), a point cloud as its count and each field's range."""

from __future__ import annotations

import base64
import io
from typing import Any

import mcp_types as types

__all__ = ["cloud_summary", "image"]


def cloud_summary(msg: Any) -> dict[str, Any]:
    """A point cloud in a few numbers: its count and each numeric field's finite range and
    mean (its data is summarized away)."""
    import numpy as np

    from ..data import to_numpy

    points = to_numpy(msg)
    fields: dict[str, Any] = {}
    for name in points.dtype.names or ():
        column = points[name]
        if column.dtype.kind not in "iuf":
            continue
        finite = column[np.isfinite(column)] if column.dtype.kind == "f" else column
        fields[name] = ({"min": float(finite.min()), "max": float(finite.max()),
                         "mean": round(float(finite.mean()), 6)} if finite.size else None)
    return {"count": int(points.size), "fields": fields}


def image(msg: Any, fmt: str, size: int, topic: str, type_name: str, max_pixels: int
          ) -> list[types.ContentBlock]:
    """An image message as image content scaled to ``size`` pixels at most on its longer
    side, and a line saying what it was (a compressed one over ``max_pixels`` is refused
    undecoded: :func:`~roslibpy_lite.data.to_numpy`)."""
    from PIL import Image

    from ..data import to_numpy

    array = to_numpy(msg, max_pixels=max_pixels)
    encoding = str(msg.get("encoding", "")) if fmt == "PNG" else "rgb8"
    if array.ndim == 3 and encoding.startswith("bgr"):
        array = array[..., 2::-1] if array.shape[2] == 3 else array[..., [2, 1, 0, 3]]
    if array.dtype.itemsize > 1:  # 16-bit depth and the like: scaled to 8 bits to be seen
        peak = float(array.max()) or 1.0
        array = (array.astype("float64") * (255.0 / peak)).astype("uint8")
    picture = Image.fromarray(array)
    height, width = array.shape[:2]
    picture.thumbnail((size, size))
    buf = io.BytesIO()
    picture.save(buf, format=fmt)
    mime = "image/png" if fmt == "PNG" else "image/jpeg"
    note = (f"{topic} ({type_name}): {width}x{height} {encoding or 'compressed'}, "
            f"shown at {picture.width}x{picture.height}")
    return [types.ImageContent(data=base64.b64encode(buf.getvalue()).decode("ascii"),
                               mime_type=mime),
            types.TextContent(text=note)]

