"""Jupyter: output where it belongs, the connection's state and log lines in the notebook.

A Jupyter kernel (ipykernel) sends every output with the *parent* of the request that
made it, and a notebook shows it under that cell. Output written by a subscription
callback has no cell of its own: it runs on the client's loop thread (blocking client)
or in the connection's task (asyncio client), and so it went under the cell that
connected. Now each callback given to ``subscribe`` runs with the parent of the cell
that subscribed (:func:`in_cell`, applied by both clients), so its ``print`` and
``display`` land under that cell, also when it runs later. Outside a kernel nothing is
changed.

Two helpers for the notebook, each safe to run again (the earlier one is replaced)::

    from roslibpy_lite import jupyter
    jupyter.show_log()          # the client's log lines (reconnects, refusals) under this cell
    jupyter.show_state(ros)     # one line under this cell, updated on each state change
"""

from __future__ import annotations

import contextlib
import contextvars
import datetime
import functools
import logging
import sys
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol, TypeVar

from ._aio import is_async_callable

if TYPE_CHECKING:
    from ._api_types import ConnectionState, StateCallback

__all__ = ["Cell", "current_cell", "from_cell", "in_cell", "in_kernel", "show_log", "show_state",
           "write_in_cell"]

F = TypeVar("F", bound=Callable[..., Any])


class _Stream(Protocol):
    """ipykernel's OutStream and ZMQDisplayPublisher: what attributes output to a cell."""

    parent_header: dict[str, Any]

    def set_thread_parent(self, parent: dict[str, Any]) -> Any: ...

    def reset_thread_parent(self, token: Any) -> None: ...


def _streams() -> list[_Stream]:
    """stdout, stderr and the display publisher of a running ipykernel ([] outside one)."""
    if "ipykernel" not in sys.modules:
        return []
    ipython = sys.modules.get("IPython")
    shell = ipython.get_ipython() if ipython is not None else None
    candidates: list[Any] = [sys.stdout, sys.stderr, getattr(shell, "display_pub", None)]
    return [s for s in candidates if hasattr(s, "set_thread_parent")]


def in_kernel() -> bool:
    """Whether this runs in an ipykernel whose output can be attributed to cells."""
    return bool(_streams())


@contextlib.contextmanager
def _parents(captured: list[tuple[_Stream, dict[str, Any]]]) -> Iterator[None]:
    tokens = [(stream, stream.set_thread_parent(header)) for stream, header in captured]
    try:
        yield
    finally:
        for stream, token in reversed(tokens):
            with contextlib.suppress(ValueError):  # a token of another context: nothing to undo
                stream.reset_thread_parent(token)


def in_cell(callback: F) -> F:
    """``callback``, made to write its output under the cell running now (sync or async).

    Call it on the thread that runs the cell (the kernel's). Outside a kernel, or for a
    callback already made so, ``callback`` is returned as it is. The result compares
    equal to ``callback`` (so re-subscribing the same function is still recognised).
    """
    streams = _streams()
    if not streams or getattr(callback, "__roslibpy_lite_cell__", False):
        return callback
    captured = [(s, dict(s.parent_header)) for s in streams]
    cls = _AttributedAsync if is_async_callable(callback) else _Attributed
    return cls(callback, captured)  # type: ignore[return-value]


class _Attributed:
    """A callback wrapped by :func:`in_cell`: equal (and hashing equal) to the original, and
    reading as it (``__code__``, ``__closure__``, ``__self__``...), so that code comparing
    callbacks (a re-run cell's subscribe) sees the function it was given."""

    __roslibpy_lite_cell__ = True
    __wrapped__: Callable[..., Any]

    def __init__(self, original: Callable[..., Any],
                 captured: list[tuple[_Stream, dict[str, Any]]]) -> None:
        functools.update_wrapper(self, original)
        self._captured = captured

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        with _parents(self._captured):
            return self.__wrapped__(*args, **kwargs)

    def __getattr__(self, name: str) -> Any:
        if name == "__wrapped__":  # not set yet (inside update_wrapper)
            raise AttributeError(name)
        return getattr(self.__wrapped__, name)

    def __eq__(self, other: object) -> bool:
        return other is self or other == self.__wrapped__

    def __hash__(self) -> int:
        return hash(self.__wrapped__)

    def __repr__(self) -> str:
        return f"<in_cell {self.__wrapped__!r}>"


def write_in_cell(callback: Any, text: str) -> bool:
    """Write ``text`` to stderr under the cell that ``callback`` was made for by
    :func:`in_cell`; False (nothing written) when it was not made so (outside a kernel)."""
    captured = getattr(callback, "_captured", None)
    if not getattr(callback, "__roslibpy_lite_cell__", False) or captured is None:
        return False
    with _parents(captured):
        sys.stderr.write(text if text.endswith("\n") else text + "\n")
    return True


class Cell(NamedTuple):
    """The notebook cell a call was made from (:func:`current_cell`)."""

    key: str
    """The same for every run of the cell: the id the front end gives it, else its code."""
    run: str
    """This run's request id (a re-run has another)."""
    number: int | None
    """This run's execution count (``In [count]``), where the kernel says."""


_CELL: contextvars.ContextVar[Cell | None] = contextvars.ContextVar(
    "roslibpy_lite_cell", default=None)
"""The cell a blocking client's call came from, set on its loop thread for that call."""


def current_cell() -> Cell | None:
    """The cell running now (None outside a kernel, or outside a cell's execution).

    On a blocking client's loop thread it is the cell whose call is being served there
    (handed over by the client)."""
    given = _CELL.get()
    if given is not None or "ipykernel" not in sys.modules:
        return given
    ipython = sys.modules.get("IPython")
    shell = ipython.get_ipython() if ipython is not None else None
    kernel = getattr(shell, "kernel", None)
    try:
        parent: dict[str, Any] = kernel.get_parent("shell") if kernel is not None else {}
    except Exception:  # an older or other kernel: no cell to name
        return None
    header = parent.get("header") or {}
    if header.get("msg_type") != "execute_request":
        return None
    cell_id = (parent.get("metadata") or {}).get("cellId")
    code = (parent.get("content") or {}).get("code", "")
    count = getattr(shell, "execution_count", None)
    return Cell(str(cell_id or code), str(header.get("msg_id", "")),
                count if isinstance(count, int) else None)


@contextlib.contextmanager
def from_cell(cell: Cell | None) -> Iterator[None]:
    """Within it, :func:`current_cell` is ``cell`` (a blocking client hands its caller's
    cell over to its loop thread so)."""
    token = _CELL.set(cell)
    try:
        yield
    finally:
        _CELL.reset(token)


class _AttributedAsync(_Attributed):
    """An async callback wrapped by :func:`in_cell`."""

    async def __call__(self, *args: Any, **kwargs: Any) -> Any:
        with _parents(self._captured):
            return await self.__wrapped__(*args, **kwargs)


# -- log lines and state in the notebook ---------------------------------------------------------

_LOG_HANDLER: logging.Handler | None = None


class _CellHandler(logging.StreamHandler):  # type: ignore[type-arg]
    """Writes records to stderr under the cell that made it (a stream looked up at each emit,
    as the kernel's stderr may be replaced)."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)
        self.captured = [(s, dict(s.parent_header)) for s in _streams()]

    def emit(self, record: logging.LogRecord) -> None:
        self.setStream(sys.stderr)
        with _parents(self.captured):
            super().emit(record)


def show_log(level: int = logging.INFO, *, logger: str = "roslibpy_lite") -> logging.Handler:
    """Show the client's log lines (``roslibpy_lite.*``, ``level`` and up) under this cell,
    as ``HH:MM:SS LEVEL name: text``. Running it again moves them to the new cell (the
    earlier handler is removed). Returns the handler (``logging.getLogger(logger)
    .removeHandler(h)`` to stop)."""
    global _LOG_HANDLER
    target = logging.getLogger(logger)
    if _LOG_HANDLER is not None:
        for name in ("roslibpy_lite", logger):
            logging.getLogger(name).removeHandler(_LOG_HANDLER)
    handler = _CellHandler()
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s",
                                           "%H:%M:%S"))
    target.addHandler(handler)
    if target.getEffectiveLevel() > level or target.level == logging.NOTSET:
        target.setLevel(level)
    _LOG_HANDLER = handler
    return handler


class _Watched(Protocol):
    """A client of either kind: what :func:`show_state` reads."""

    @property
    def state(self) -> ConnectionState: ...

    def on_state_change(self, callback: StateCallback) -> Callable[[], None]: ...


_STATE_WATCHES: dict[int, Callable[[], None]] = {}


def show_state(ros: _Watched, *, label: str = "") -> Callable[[], None]:
    """Show the connection's state as one line under this cell, updated on every change
    (``label: connected since 12:00:03 (2 reconnects)``). Works on the asyncio and the
    blocking client; running it again for the same client moves the line here. Outside a
    kernel the line is printed at each change. Returns a function that stops the updates.
    """
    name = label or getattr(getattr(ros, "aio", ros), "url", None) or type(ros).__name__
    drops = 0

    def line(state: ConnectionState) -> str:
        since = datetime.datetime.now().strftime("%H:%M:%S")
        again = f" ({drops} reconnect{'s' * (drops != 1)})" if drops else ""
        return f"{name}: {state.value} since {since}{again}"

    handle: Any = None
    if in_kernel():
        from IPython.display import display

        handle = display({"text/plain": line(ros.state)}, raw=True,  # type: ignore[no-untyped-call]
                         display_id=True)
    else:
        print(line(ros.state))

    def changed(state: ConnectionState) -> None:
        nonlocal drops
        if state.value == "reconnecting":
            drops += 1
        if handle is not None:
            handle.update({"text/plain": line(state)}, raw=True)
        else:
            print(line(state))

    earlier = _STATE_WATCHES.pop(id(ros), None)
    if earlier is not None:
        earlier()
    stop = _Quiet(ros.on_state_change(in_cell(changed)))
    _STATE_WATCHES[id(ros)] = stop
    return stop


class _Quiet:
    """A function that a notebook cell ending with it does not show (no ``Out[n]``)."""

    def __init__(self, fn: Callable[[], None]) -> None:
        self._fn = fn

    def __call__(self) -> None:
        self._fn()

    def _ipython_display_(self) -> None:
        """Shown as nothing."""

    def __repr__(self) -> str:
        return "<stop showing the state>"
