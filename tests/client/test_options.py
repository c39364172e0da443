"""``ClientOptions`` (what ``connect`` and ``sync.connect`` take) is ``Client``'s option list."""

from __future__ import annotations

import inspect
import typing

import roslibpy_lite
from roslibpy_lite import sync
from roslibpy_lite.client import Client, ClientOptions


def _client_options() -> dict[str, object]:
    hints = typing.get_type_hints(Client.__init__)
    params = inspect.signature(Client.__init__).parameters.values()
    return {p.name: hints[p.name] for p in params if p.kind is p.KEYWORD_ONLY}


def test_client_options_name_every_option_of_client_with_its_type() -> None:
    """Each keyword option of ``Client`` is in ``ClientOptions`` with the same type, and no more."""
    assert typing.get_type_hints(ClientOptions) == _client_options()


def test_connect_functions_take_client_options() -> None:
    """``connect`` and ``sync.connect`` take the url and ``**ClientOptions``, and each its own
    ``replace`` (whether to close an open client of the same URL)."""
    for fn, own in ((roslibpy_lite.connect, ["replace"]), (sync.connect, ["replace"])):
        params = list(inspect.signature(fn).parameters.values())
        assert [(p.name, p.kind) for p in params] == [
            ("url", inspect.Parameter.POSITIONAL_OR_KEYWORD),
            *((name, inspect.Parameter.KEYWORD_ONLY) for name in own),
            ("options", inspect.Parameter.VAR_KEYWORD)], fn
        assert params[-1].annotation == "Unpack[ClientOptions]", fn
