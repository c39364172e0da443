"""The loop thread under a blocking client: an asyncio loop on a thread of its own.

:class:`LoopThread` hands coroutines to its loop and blocks the calling
thread for their results (cancelling them if the wait is interrupted), and
owns the worker pool that runs blocking service handlers.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import inspect
import threading
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

from ..exceptions import ConnectionClosed, UsageError

__all__ = ["HANDLER_THREADS", "LoopThread"]

T = TypeVar("T")

HANDLER_THREADS = 8
"""Service requests a blocking client handles at once (one worker thread each)."""


async def _tracked(coro: Coroutine[Any, Any, T], done: threading.Event) -> T:
    try:
        return await coro
    finally:
        done.set()


def _start(
    loop: asyncio.AbstractEventLoop, coro: Coroutine[Any, Any, T],
    future: concurrent.futures.Future[T], skipped: Callable[[], Any] | None,
) -> None:
    """On the loop: run ``coro`` as a task whose outcome goes to ``future`` (both ways)."""
    if future.cancelled():  # cancelled during the hand-off: never start it
        coro.close()
        if skipped is not None:
            skipped()
        return
    task = loop.create_task(coro)

    def settle(t: asyncio.Task[T]) -> None:
        with contextlib.suppress(concurrent.futures.InvalidStateError):  # cancelled meanwhile
            if t.cancelled():
                future.cancel()
            elif (exc := t.exception()) is not None:
                future.set_exception(exc)
            else:
                future.set_result(t.result())

    def cancel_task(f: concurrent.futures.Future[T]) -> None:
        if f.cancelled():
            with contextlib.suppress(RuntimeError):  # the loop is already closed
                loop.call_soon_threadsafe(task.cancel)

    task.add_done_callback(settle)
    future.add_done_callback(cancel_task)


async def _call_async(fn: Callable[..., Any], args: tuple[Any, ...], kwargs: dict[str, Any]) -> Any:
    result = fn(*args, **kwargs)
    if inspect.isawaitable(result):
        result = await result
    return result


class LoopThread:
    """An asyncio event loop on a daemon thread of its own, plus a worker pool.

    :meth:`run` hands a coroutine to the loop and blocks the calling thread
    until it finishes; if the wait is interrupted (Ctrl+C), the coroutine is
    cancelled on the loop before the interruption propagates.
    """

    def __init__(self, name: str) -> None:
        self.name = name
        self.loop = asyncio.new_event_loop()
        self.handlers = concurrent.futures.ThreadPoolExecutor(
            max_workers=HANDLER_THREADS, thread_name_prefix=f"{name} handler"
        )
        self.closed = False
        self._stopping = False
        # Held while handing work to the loop and while starting to stop it: nothing is
        # handed over once stop() has begun (it would never run, and its caller never return).
        self._submit_lock = threading.Lock()
        self._thread = threading.Thread(target=self._main, name=name, daemon=True)
        self._thread.start()

    def _main(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.loop.run_forever()

    @property
    def closing(self) -> bool:
        """True once :meth:`stop` has begun (no work is handed to the loop any more)."""
        return self._stopping or self.closed

    def in_loop(self) -> bool:
        """True when called from the loop thread itself (from a callback)."""
        return threading.get_ident() == self._thread.ident

    def run(self, coro: Coroutine[Any, Any, T], what: str) -> T:
        """Run ``coro`` on the loop and return its result (``what`` names it in errors).

        Raises:
            UsageError: called from the loop thread (it would wait for ever).
            ConnectionClosed: the loop was stopped.
            KeyboardInterrupt: the wait was interrupted; ``coro`` was cancelled.
        """
        if self.in_loop():
            coro.close()
            raise UsageError(
                f"{what}: a blocking call from a callback (on the client's loop thread) "
                "would wait for ever; publish from callbacks, or hand the work to another thread"
            )
        done = threading.Event()
        # The future is known here before the work reaches the loop, so a Ctrl+C at any
        # point of the hand-off can still cancel it (else it would go on holding what it
        # holds there: a subscription's reader, a call).
        handed: list[concurrent.futures.Future[T]] = []
        try:
            future = self.submit(_tracked(coro, done), what, handed.append, done.set)
            return self.wait(future, what, done)
        except ConnectionClosed:
            if not handed:
                coro.close()  # never started: no "never awaited" warning
            raise
        except BaseException:
            if handed and not handed[0].done():
                handed[0].cancel()
                done.wait(5.0)
            raise

    def submit(
        self, coro: Coroutine[Any, Any, T], what: str,
        keep: Callable[[concurrent.futures.Future[T]], Any] | None = None,
        skipped: Callable[[], Any] | None = None,
    ) -> concurrent.futures.Future[T]:
        """Hand ``coro`` to the loop without waiting; its future (``what`` names it in errors).

        ``keep(future)`` is called before the work is scheduled, so a caller
        interrupted during the hand-off already holds the future to cancel.
        Cancelling the future cancels the work on the loop, or it never starts
        and ``skipped()`` is called there.

        Raises:
            ConnectionClosed: the loop is stopped or stopping (``coro`` is closed, not run).
        """
        with self._submit_lock:
            if self.closing:
                coro.close()
                raise ConnectionClosed(f"{what}: the client is closed")
            future: concurrent.futures.Future[T] = concurrent.futures.Future()
            if keep is not None:
                keep(future)
            self.loop.call_soon_threadsafe(_start, self.loop, coro, future, skipped)
            return future

    def wait(
        self, future: concurrent.futures.Future[T], what: str,
        done: threading.Event | None = None,
    ) -> T:
        """The result of ``future`` (running on the loop); cancels it if the wait is interrupted.

        ``done`` is set once the cancelled work has really ended there.
        """
        try:
            return future.result()
        except concurrent.futures.CancelledError:
            if self._stopping:  # cancelled by close(), not by this caller
                raise ConnectionClosed(f"{what}: the client was closed") from None
            raise
        except BaseException:
            if not future.done():  # interrupted while waiting (Ctrl+C): cancel it there
                future.cancel()
                if done is not None:
                    done.wait(5.0)
            raise

    def call(self, what: str, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """Run ``fn(*args, **kwargs)`` on the loop (awaiting its result if it is awaitable).

        ``what`` names the operation in errors.
        """
        return self.run(_call_async(fn, args, kwargs), what)

    def off_loop(self, fn: Callable[[Any], T]) -> Callable[[Any], Coroutine[Any, Any, T]]:
        """An ``async`` function that runs the plain ``fn(arg)`` on the worker pool."""
        pool, loop = self.handlers, self.loop

        async def run(arg: Any) -> T:
            return await loop.run_in_executor(pool, fn, arg)

        return run

    def stop(self) -> None:
        """Cancel what is left on the loop, stop the worker pool and the thread. Idempotent."""
        if self.in_loop():
            raise UsageError("close: cannot close the client from one of its own callbacks")
        with self._submit_lock:
            if self.closing:
                return
            # Submitted under the lock: every task handed over before is on the loop already.
            done = threading.Event()
            finish = asyncio.run_coroutine_threadsafe(_tracked(self._finish(), done), self.loop)
            self._stopping = True
        self.wait(finish, "close", done)
        self.closed = True
        # From a handler's own thread, joining the pool would wait for itself.
        self.handlers.shutdown(wait=not threading.current_thread().name.startswith(
            f"{self.name} handler"))
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join()
        self.loop.close()

    async def _finish(self) -> None:
        tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        await self.loop.shutdown_asyncgens()
        await self.loop.shutdown_default_executor()  # getaddrinfo's threads
