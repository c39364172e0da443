"""Global options may stand before or after the subcommand."""

from __future__ import annotations

import pytest

from roslibpy_lite.cli import DEFAULT_URL, build_parser


@pytest.mark.parametrize(
    "argv",
    [
        ["--url", "ws://robot:1", "--timeout", "3", "topic", "list"],
        ["topic", "list", "--url", "ws://robot:1", "--timeout", "3"],
        ["--url", "ws://robot:1", "service", "call", "/s", "std_srvs/srv/Trigger", "--timeout", "3"],
    ],
)
def test_url_and_timeout_anywhere(argv: list[str]) -> None:
    """--url and --timeout are taken wherever they stand on the line."""
    args = build_parser().parse_args(argv)
    assert (args.url, args.timeout) == ("ws://robot:1", 3.0)


def test_url_defaults_to_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without --url, $ROSLIBPY_LITE_URL and then the default URL apply."""
    monkeypatch.delenv("ROSLIBPY_LITE_URL", raising=False)
    assert build_parser().parse_args(["node", "list"]).url == DEFAULT_URL
    monkeypatch.setenv("ROSLIBPY_LITE_URL", "ws://env:2")
    assert build_parser().parse_args(["node", "list"]).url == "ws://env:2"
