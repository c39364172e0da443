"""One robot's types and graph documents as a relay reads them, bounded in time as in bytes.

A relay serves every robot on one event loop. What a robot sends that costs the relay time
without breaking a byte bound must not cost the other robots' clients that time (issue 53):
a 3.4 MB graph document of 90,000 topics ten times a second gave another robot's viewer
2.3-2.55 s of latency (7.6 s on a loaded test machine), and a type redefined four times a
second (two ~190 KB definitions) 4.2 s, each decoded or built on the loop. So:

- a robot's graph documents are read at most once each :data:`GRAPH_INTERVAL` s (1 s); one
  that comes sooner waits, and a newer one replaces it (counted ``graph_superseded``);
- each is decoded, and every type its definitions name is built, on a worker thread
  (:func:`prepare`): the loop only swaps the result in, so what resolves a type on the loop
  (a session's subscribe, a sample's type) finds it built and never parses;
- a document that redefines a type already built (a new store, every type built again) is
  applied at most once each :data:`REDEFINE_INTERVAL` s; until its turn it waits as any
  document does (the newest wins);
- a message type of more than :data:`MAX_FIELDS` fields is refused before it is built: the
  classes' code is compiled in one piece, during which no other thread runs (12,000 fields
  took 4.5 s of it), so the worker's build must come in small pieces to leave the loop its
  turns.

One worker thread serves every robot of the relay, each robot with at most one document in
it at a time. :class:`RobotTypes` is one robot's store of classes; :class:`GraphReader` is
the path of its graph documents from the inbox to the loop.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import gc
import logging
import queue
import re
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ParamSpec, TypeVar

from bridge_server.zenoh.inbox import Faults
from bridge_server.zenoh.keys import Snapshot
from msgs.dynamic import DELIMITER, LimitError, TypeStore, split
from msgs.parser import PRIMITIVE_TYPES
from msgs.runtime import UnknownTypeError as WireUnknownType
from rosbridge_core.interfaces import BridgeError, UnknownTypeError, canonical_name

__all__ = ["GRAPH_INTERVAL", "MAX_DEFINITION_BYTES", "MAX_FIELDS", "MAX_TYPES_PER_ROBOT",
           "REDEFINE_INTERVAL", "GraphReader", "Prepared", "RobotTypes", "TypeLimits",
           "TypeRefused", "let_go", "prepare"]

log = logging.getLogger("bridge_server.zenoh.graph")

_P = ParamSpec("_P")
_T = TypeVar("_T")

GRAPH_INTERVAL = 1.0
"""Seconds between two graph documents of a robot that the relay reads (at most one a
second; one coming sooner waits for its turn, and a newer one replaces it). A robot's graph
changes seldom; each 3.6 MB document read costs the other robots' loop turns (Python's lock
while it is decoded and its objects are walked), so the fewer the better."""

REDEFINE_INTERVAL = 2.0
"""Seconds between two graph documents of a robot that redefine a type the relay built (each
builds every type of the robot again)."""

MAX_DEFINITION_BYTES = 256 * 1024
"""Largest definition text (UTF-8 bytes, a type with its dependencies) the relay builds a
robot's type from (``--max-definition-bytes``). The largest of the standard types
(``visualization_msgs/msg/MarkerArray`` with its dependencies) is under 20 KB; a robot's
1.2 MB text made the relay spend 70 ms per sample before types were built once per text."""

MAX_TYPES_PER_ROBOT = 1000
"""Most messages, services and actions the relay builds from one robot's definitions
(``--max-types-per-robot``); each costs about 30 KB of the relay's memory (3,000 types took
100 MB), so a robot's types stay under ~30 MB. Types ``msgs`` generates are not counted."""

MAX_FIELDS = 1000
"""Most lines (fields and constants) of one message in a robot's definition
(``--max-fields-per-type``). The standard types have at most a few dozen; building a class
compiles its code in one piece, during which the loop cannot run: 1,000 fields held it
~20 ms, 12,000 fields 4.5 s."""


@dataclass(frozen=True)
class TypeLimits:
    """What the relay takes of each robot's type definitions (see the constants)."""

    definition_bytes: int = MAX_DEFINITION_BYTES
    types: int = MAX_TYPES_PER_ROBOT
    fields: int = MAX_FIELDS


_LIMIT_OPTIONS = {"max_definition_bytes": "--max-definition-bytes",
                  "max_types": "--max-types-per-robot", "max_fields": "--max-fields-per-type"}


class TypeRefused(UnknownTypeError):
    """A robot's type over one of the relay's :class:`TypeLimits` (its messages dropped)."""


class _Worker(concurrent.futures.Executor):
    """One daemon thread running what is submitted, in order: a process that stops does not
    wait for a robot's build, and what a job held is freed on the thread (:func:`let_go`)."""

    def __init__(self) -> None:
        self._jobs: queue.SimpleQueue[tuple[concurrent.futures.Future[Any],
                                            Callable[..., Any], tuple[Any, ...]]] = (
            queue.SimpleQueue())
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def submit(self, fn: Callable[_P, _T], /, *args: _P.args, **kwargs: _P.kwargs
               ) -> concurrent.futures.Future[_T]:
        """Run ``fn(*args)`` on the thread (no keyword arguments)."""
        assert not kwargs, "the worker takes positional arguments only"
        future: concurrent.futures.Future[_T] = concurrent.futures.Future()
        with self._lock:
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="robot-types",
                                                daemon=True)
                self._thread.start()
        self._jobs.put((future, fn, args))
        return future

    def _run(self) -> None:
        while True:
            future, fn, args = self._jobs.get()
            if future.set_running_or_notify_cancel():
                try:
                    future.set_result(fn(*args))
                except BaseException as exc:  # handed to whoever waits for it
                    future.set_exception(exc)
            del future, fn, args  # what the job held goes here, not on the loop


_worker: _Worker | None = None


def _executor() -> _Worker:
    """The one thread that reads every robot's graph documents and builds their types."""
    global _worker
    if _worker is None:
        _worker = _Worker()
    return _worker


def _check_fields(type_name: str, text: str, limit: int) -> None:
    """:class:`LimitError` if a message of ``text`` has more than ``limit`` lines that are
    not blank or comments (a service's or action's parts counted together)."""
    for name, body in split(type_name, text):
        lines = sum(1 for line in body.splitlines() if line.partition("#")[0].strip())
        if lines > limit:
            raise LimitError(name, "max_fields", limit, lines,
                             "the number of fields and constants of one message")


def build(store: TypeStore, name: str, text: str, limits: TypeLimits) -> Any:
    """The class of ``name`` built from ``text`` in ``store``, or why not: a
    :class:`LimitError` over a limit, an :class:`UnknownTypeError` if it does not build."""
    try:
        _check_fields(name, text, limits.fields)
        blocks = split(name, text)
        if len(blocks) > PIECES:
            _in_pieces(store, name, text, blocks, limits)
        return store.load(name, text)
    except LimitError as exc:
        return exc
    except Exception as exc:  # a definition that does not parse, or too deep to
        return UnknownTypeError(name, f"{store.name}'s definition of it does not build "
                                f"({type(exc).__name__}: {str(exc)[:200]})")


PIECES = 50
"""A definition of more message types than this is built this many at a time (each piece
after those it uses), not as one module: compiling one module of 650 types held Python's
lock ~0.2 s on an idle machine, 0.6 s on a busy one, and the loop waited that long; one type
at a time took 900 types 15 s."""


def _in_pieces(store: TypeStore, name: str, text: str, blocks: list[tuple[str, str]],
               limits: TypeLimits) -> None:
    """Define the dependencies of ``name`` (``blocks`` of ``text`` after its own)
    :data:`PIECES` at a time, each piece after those it uses, so that each compiles apart
    (Python's lock is free between them); the limits said before any is defined. A piece
    that does not build (an order misread here) is left to the whole text's load."""
    size = len(text.encode())
    if size > limits.definition_bytes:
        raise LimitError(name, "max_definition_bytes", limits.definition_bytes, size,
                         "the definition's size in bytes")
    deps = {dep: body for dep, body in blocks[1:] if not _known(store, dep)}
    total = len(store) + len(deps) + (name.split("/")[1] != "msg")
    if total > limits.types:
        raise LimitError(name, "max_types", limits.types, total,
                         f"the number of types of {store.name} with this one's")
    order = _dependencies_first(deps)
    for start in range(0, len(order), PIECES):
        *rest, head = order[start:start + PIECES]
        piece = _ending(deps[head]) + "".join(
            f"{DELIMITER}\nMSG: {dep}\n{_ending(deps[dep])}" for dep in rest)
        try:
            store.load(head, piece)  # its dependency blocks are defined with it
        except LimitError:
            raise
        except Exception:  # its order misread: the whole text's load says what is wrong
            return


def _ending(body: str) -> str:
    return body if body.endswith("\n") else body + "\n"


def _known(store: TypeStore, name: str) -> bool:
    try:
        store.lookup(name)
    except WireUnknownType:
        return False
    return True


def _uses(name: str, body: str) -> list[str]:
    """The message types a block of message ``name`` names (``pkg/msg/Name``)."""
    package = name.split("/")[0]
    used = []
    for line in body.splitlines():
        code = line.partition("#")[0].split()
        if not code or code[0] == "---":
            continue
        base = re.split(r"[\[<]", code[0], maxsplit=1)[0]
        if base in PRIMITIVE_TYPES:
            continue
        parts = [p for p in base.split("/") if p != "msg"]
        used.append(f"{parts[0]}/msg/{parts[-1]}" if len(parts) > 1
                    else f"{package}/msg/{parts[0]}")
    return used


def _dependencies_first(deps: Mapping[str, str]) -> list[str]:
    """``deps``' names, each after the ones of ``deps`` it uses (depth first, no recursion:
    a chain of 999 types is no deeper here than one)."""
    order: list[str] = []
    placed: set[str] = set()
    for root in deps:
        stack = [(root, iter(_uses(root, deps[root])))]
        placed.add(root)
        while stack:
            node, uses = stack[-1]
            nxt = next((u for u in uses if u in deps and u not in placed), None)
            if nxt is None:
                stack.pop()
                order.append(node)
            else:
                placed.add(nxt)
                stack.append((nxt, iter(_uses(nxt, deps[nxt]))))
    return order


@dataclass
class Prepared:
    """A graph document read on the worker: the snapshot, every type of its definitions as
    (its text, its class or why not), and, when it redefined a built type, the new store
    they are in (``None``: the robot's store, grown)."""

    snapshot: Snapshot
    built: dict[str, tuple[str, Any]]
    store: TypeStore | None = None
    redefined: str = ""
    waits: bool = False
    """It redefines a type and may not yet (:data:`REDEFINE_INTERVAL`): read again later."""


def prepare(data: bytes, store: TypeStore, built: Mapping[str, tuple[str, Any]],
            limits: TypeLimits, may_redefine: bool, new_store: Callable[[], TypeStore]
            ) -> Prepared:
    """On the worker: decode a graph document and build the types its definitions name (see
    :class:`Prepared`); ``BridgeError`` naming what is wrong with the document. Python's
    collector is off meanwhile: the document's objects die or stay before it would walk
    them, and a walk over every object, on this thread, holds the lock the loop waits for
    (a 90,000-topic document's cost the loop ~1 s, a 650-type build's up to 1 s)."""
    collecting = gc.isenabled()
    gc.disable()
    try:
        return _prepare(data, store, built, limits, may_redefine, new_store)
    finally:
        if collecting:
            gc.enable()


def _prepare(data: bytes, store: TypeStore, built: Mapping[str, tuple[str, Any]],
             limits: TypeLimits, may_redefine: bool, new_store: Callable[[], TypeStore]
             ) -> Prepared:
    try:
        snap = Snapshot.decode(data)
    except RecursionError:  # too deep for json: not a Snapshot either
        raise BridgeError("a robot's @graph payload is nested too deeply") from None
    fresh = dict(built)
    redefined = next((name for name, text in snap.definitions.items()
                      if name in fresh and fresh[name][0] != text
                      and not isinstance(fresh[name][1], Exception)), "")
    if redefined and not may_redefine:
        return Prepared(snap, fresh, waits=True)
    target = store
    if redefined:
        target, fresh = new_store(), {}
    for name, text in snap.definitions.items():
        if name not in fresh or fresh[name][0] != text:
            fresh[name] = (text, build(target, name, text, limits))
    return Prepared(snap, fresh, target if redefined else None, redefined)


def let_go(old: Any) -> None:
    """Drop the last reference to ``old`` on the worker: freeing a 90,000-topic graph
    document takes ~70 ms, which the loop would spend otherwise."""
    _executor().submit(_keep_until_run, old)


def _keep_until_run(_old: Any) -> None:
    """Nothing: ``_old`` is freed on the worker when this returns."""


class RobotTypes:
    """One robot's types as the relay has built them: its store (:attr:`store`), and per
    type the text it was built from with the class or the refusal."""

    def __init__(self, robot: str, limits: TypeLimits) -> None:
        self.robot = robot
        self.limits = limits
        self.store = self.new_store()
        self.built: dict[str, tuple[str, Any]] = {}
        self.generation = 0
        """Raised each time the store is replaced: a document prepared for an older one is
        read again."""
        self._limits_said: set[str] = set()

    def new_store(self) -> TypeStore:
        """An empty store within the limits."""
        return TypeStore(f"robot {self.robot}", max_types=self.limits.types,
                         max_definition_bytes=self.limits.definition_bytes)

    def take(self, prepared: Prepared) -> None:
        """(On the loop.) The types of a prepared document, refusals said once per limit; a
        new store replaces the old one, which is closed on the worker."""
        if prepared.store is not None:
            self._replace(prepared.store)
            log.warning("robot %s: its definition of %s changed; this relay reads its types "
                        "anew from its new definitions", self.robot, prepared.redefined)
        self.built = {name: (text, self.refuse(found) if isinstance(found, LimitError)
                             else found) for name, (text, found) in prepared.built.items()}

    def release(self) -> int:
        """Forget every type (the robot left and nothing uses them); how many there were."""
        count = len(self.store)
        self._replace(self.new_store())
        self.built = {}
        return count

    def _replace(self, store: TypeStore) -> None:
        old, self.store = self.store, store
        self.generation += 1
        _executor().submit(old.close)  # it waits for the worker's builds: not on the loop

    def load(self, name: str, kind: str, definitions: Mapping[str, str]) -> Any:
        """The class of ``name``: the one built from the robot's definition (built here, on
        the loop, only if the worker has not: a type released and asked for again), else
        the generated one."""
        canonical = canonical_name(name, kind)  # type: ignore[arg-type]
        text = definitions.get(canonical)
        store = self.store
        try:
            if not text:
                return {"msg": store.lookup_message, "srv": store.lookup_service,
                        "action": store.lookup_action}[kind](canonical)
            built = self.built.get(canonical)
            if built is None or not (built[0] is text or built[0] == text):
                if built is not None and not isinstance(built[1], Exception):
                    self._replace(self.new_store())
                    self.built = {}
                    log.warning("robot %s: its definition of %s changed; this relay reads its "
                                "types anew from its new definitions", self.robot, canonical)
                found = build(self.store, canonical, text, self.limits)
                if isinstance(found, LimitError):
                    found = self.refuse(found)
                built = self.built[canonical] = (text, found)
            if isinstance(built[1], UnknownTypeError):  # a new one: raising one again grows it
                raise type(built[1])(built[1].name, built[1].reason)
            return built[1]
        except WireUnknownType as exc:
            raise UnknownTypeError(name, f"robot {self.robot} does not list it and msgs does "
                                   f"not generate it ({exc})") from None

    def refuse(self, exc: LimitError) -> TypeRefused:
        """The refusal of a type over a limit, said in the log once per limit and robot."""
        option = _LIMIT_OPTIONS.get(exc.limit, exc.limit)
        why = f"{exc.what} ({exc.got}) is over this relay's {option} ({exc.allowed})"
        if exc.limit not in self._limits_said:
            self._limits_said.add(exc.limit)
            log.warning("robot %s: type %s refused: %s; its messages are dropped (counted, "
                        "not logged again for this limit)", self.robot, exc.type_name, why)
        return TypeRefused(exc.type_name, f"robot {self.robot}'s definition is refused: {why}")


class GraphReader:
    """The robot's graph documents from its inbox to the loop (see the module's text): at
    most one each :data:`GRAPH_INTERVAL` s, one at a time on the worker, the newest waiting
    replacing the one before; ``apply`` takes each document read (on the loop), after
    :attr:`types` took its types."""

    def __init__(self, loop: asyncio.AbstractEventLoop, types: RobotTypes, faults: Faults,
                 apply: Callable[[Snapshot], None]) -> None:
        self.loop = loop
        self.types = types
        self.faults = faults
        self.apply = apply
        self._waiting: bytes | None = None
        self._busy = False
        self._timer: asyncio.TimerHandle | None = None
        self._next = 0.0  # loop time from which the next document is read
        self._next_redefinition = 0.0
        self._closed = False

    def offer(self, data: bytes) -> None:
        """(On the loop.) A graph document came: read when its turn comes."""
        if self._waiting is not None:
            self.faults.add("graph_superseded", "graph documents replaced by a newer one "
                            f"before this relay read them (it reads one each "
                            f"{GRAPH_INTERVAL:g} s at most)")
        self._waiting = data
        self._turn()

    def close(self) -> None:
        """Read nothing more (what is on the worker is dropped when it ends)."""
        self._closed = True
        self._waiting = None
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _turn(self) -> None:
        if self._busy or self._timer is not None or self._waiting is None or self._closed:
            return
        now = self.loop.time()
        if now < self._next:
            self._timer = self.loop.call_at(self._next, self._timer_ended)
            return
        data, self._waiting = self._waiting, None
        self._next = now + GRAPH_INTERVAL
        self._busy = True
        types = self.types
        job = self.loop.run_in_executor(
            _executor(), prepare, data, types.store, dict(types.built), types.limits,
            now >= self._next_redefinition, types.new_store)
        generation = types.generation
        job.add_done_callback(lambda done: self._read(done, data, generation))

    def _timer_ended(self) -> None:
        self._timer = None
        self._turn()

    def _read(self, job: asyncio.Future[Prepared], data: bytes, generation: int) -> None:
        """(On the loop.) A document came back from the worker."""
        self._busy = False
        if self._closed or job.cancelled():
            return
        try:
            prepared = job.result()
        except BridgeError as exc:
            self.faults.add("bad_graph", f"a graph document dropped: {str(exc)[:200]}")
            prepared = None
        if prepared is not None and (prepared.waits or generation != self.types.generation):
            if prepared.waits:  # a redefinition before its turn: read again then
                self._next = max(self._next, self._next_redefinition)
            if self._waiting is None:
                self._waiting = data
            let_go(prepared)
            prepared = None
        if prepared is not None:
            if prepared.store is not None:
                self._next_redefinition = self.loop.time() + REDEFINE_INTERVAL
            elif prepared.store is None and self.types.built.keys() - prepared.built.keys():
                prepared.built = {**self.types.built, **prepared.built}  # built meanwhile
            self.types.take(prepared)
            self.apply(prepared.snapshot)
        self._turn()
