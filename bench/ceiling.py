"""What rclpy alone carries, no bridge (the ``rclpy_ceiling`` scenario; ``image`` measures its
ceiling the same way): small strings and 640x480 images between two rclpy processes."""

from __future__ import annotations

from typing import Any

from bench.harness import IMAGE_GRACE, IMAGE_PUBLISHER, Ctx


async def rclpy_ceiling(ctx: Ctx) -> dict[str, Any]:
    """One rclpy publisher process to one rclpy subscriber process, no bridge, as fast as possible."""
    topic = "/bench/ceiling"
    d = ctx.duration
    out: dict[str, Any] = {}
    for label, rate in (("max", 0.0), ("at_10k", 10_000.0)):
        sub = await ctx.ros("subscribe", "--topic", topic, "--duration", str(d + 20),
                            "--idle", "1.0").start()
        pub = await ctx.ros("publish", "--topic", topic, "--rate", str(rate), "--duration", str(d),
                            "--settle", "0.3").start()
        done = await pub.event("done", d + 40)
        got = await sub.event("done", 40)
        await pub.close()
        await sub.close()
        out[label] = {
            "published": done["sent"],
            "publish_rate": round(done["rate"]),
            "received": got["received"],
            "receive_rate": round(got["rate"]),
            "delivered_pct": round(100.0 * got["received"] / max(done["sent"], 1), 2),
        }
    out["image_640x480"] = await image_ceiling(ctx)
    return out


async def image_ceiling(ctx: Ctx) -> dict[str, Any]:
    """What rclpy alone delivers: :data:`IMAGE_PUBLISHER` to a raw rclpy subscriber (nothing
    deserialised; the history depth of 50 the bridge gives image subscriptions), no bridge."""
    topic = "/bench/ceiling_image"
    d = ctx.duration
    sub = await ctx.ros("subscribe", "--kind", "image", "--topic", topic, "--depth", "50",
                        "--duration", str(d + 20), "--idle", "1.0").start()
    pub = await ctx.ros("publish", "--topic", topic, *IMAGE_PUBLISHER, "--duration",
                        str(d)).start()
    try:
        done = await pub.event("done", d + 40)
        got = await sub.event("done", 40)
    finally:
        await pub.close()
        await sub.close()
    cutoff = done["t_end"] + IMAGE_GRACE
    in_order = sum(t <= cutoff for t in got["in_order_at"])
    return {"frames_per_s": round(in_order / done["elapsed"], 1), "in_order": in_order,
            "received": got["received"], "published": done["sent"],
            "publish_s": round(done["elapsed"], 2)}
