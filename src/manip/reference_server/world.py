"""The reference server's world: the conditions a conformance run arranges, and contract 2 to ask for them.

A server's world is what the protocol cannot provoke: an obstacle in a joint's way, a calibration that
finds no zero index, a joint that lags its command, a wrist computer that falls silent, the panic
button, a force on the hand.  :class:`ReferenceWorld` arranges each on a running
:class:`~manip.reference_server.driver.ReferenceServer`:

* the conditions a connection meets from its start (an obstacle, a calibration failure, a sluggish joint,
  a silent wrist) are :class:`~manip.reference_server.conditions.WorldConditions` (the ones
  ``manip-server --fault NAME`` names), merged into the configuration that every connection opened
  while they are held reads when it opens;
* the panic button is pressed at once for the connections open now (their arm loses power, its motion
  is aborted), and stays pressed for the connections opened while it is held;
* a force on the hand is put on an in-process Cougar's hand at once
  (:class:`~manip.cougar.environment.HandLoad`), pushing so that the wrist reads the force asked for
  (plus the moment of a push at the tool point).

Clearing an arrangement takes it out again; the arrangements of one suite are cleared when it leaves.

:func:`serve_world` serves the world over TCP as ``docs/world-harness.md`` (contract 2) says: JSON Lines,
``hello`` first, then one answer per ``arrange`` or ``clear``.  ``manip-server --world tcp://127.0.0.1:0``
runs it beside the server.  Every line read is bounded (:data:`MAX_LINE`), one suite is served at a time,
and a suite that goes away has its arrangements cleared.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import AsyncIterator, Mapping
from dataclasses import dataclass, replace
from typing import Any, Final

from manip import __version__
from manip.arm.sim import Obstacle, Sluggish
from manip.cougar.environment import HandLoad
from manip.links.address import parse_address
from manip.reference_server.conditions import WorldCondition, WorldConditions
from manip.reference_server.driver import ReferenceServer

__all__ = [
    "CONTRACT",
    "MAX_LINE",
    "ReferenceWorld",
    "WorldRefusal",
    "WorldServer",
    "serve_world",
]

log = logging.getLogger("manip.reference_server.world")

CONTRACT: Final = 2
"""The contract this world speaks (``docs/world-harness.md``)."""
MAX_LINE: Final = 65536
"""Bytes of one JSON line, its newline included, that either side reads at most."""
IDLE_TIMEOUT: Final = 3600.0
"""Seconds a suite may stay silent between two messages before the world lets it go."""
NAMES: Final = (
    "obstacle",
    "calibration-failure",
    "sluggish-joint",
    "silent-wrist",
    "panic-button",
    "wrist-force",
)


class WorldRefusal(Exception):  # noqa: N818 - an answer
    """The world cannot arrange this condition here (``unsupported``, with the reason)."""


@dataclass(frozen=True)
class _Held:
    world: WorldConditions
    hand: HandLoad | None = None


def _joint(args: Mapping[str, Any], key: str = "joint", default: int | None = None) -> int:
    value = args.get(key, default)
    if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= 6:
        raise ValueError(f"{key} must be a joint number 1..6, not {value!r}")
    return value


def _number(value: object, what: str) -> float:
    if not isinstance(value, int | float) or isinstance(value, bool):
        raise ValueError(f"{what} must be a number, not {value!r}")
    return float(value)


def _optional(args: Mapping[str, Any], key: str) -> float | None:
    value = args.get(key)
    return None if value is None else _number(value, key)


def _vector(args: Mapping[str, Any], key: str) -> tuple[float, float, float]:
    value = args.get(key, [0, 0, 0])
    if not isinstance(value, list) or len(value) != 3:
        raise ValueError(f"{key} must be an array of 3 numbers, not {value!r}")
    x, y, z = (_number(v, key) for v in value)
    return x, y, z


class ReferenceWorld:
    """Conditions arranged on a running reference server; see the module docstring."""

    def __init__(self, server: ReferenceServer) -> None:
        self._server = server
        self._base = server.config
        self._held: dict[int, _Held] = {}
        self._next = 1

    @property
    def conditions(self) -> tuple[str, ...]:
        """The conditions this server's world can arrange (the wrist's need its wrist)."""
        wrist = self._server.wrist
        out = [n for n in NAMES if n not in ("silent-wrist", "wrist-force")]
        if wrist is not None:
            out.append("silent-wrist")
            if getattr(wrist, "port", None) is not None and hasattr(wrist.port, "cougar"):  # type: ignore[attr-defined]
                out.append("wrist-force")
        return tuple(out)

    def hold(self, world: WorldConditions, hand: HandLoad | None = None) -> int:
        """Hold the conditions ``world`` (and a load on the hand) until :meth:`clear`; returns its token."""
        token = self._next
        self._next += 1
        self._held[token] = _Held(world, hand)
        self._apply()
        return token

    def arrange(self, name: str, args: Mapping[str, Any]) -> int:
        """Arrange the condition ``name`` with its contract arguments; returns the token :meth:`clear`
        takes.  ValueError: bad arguments; :class:`WorldRefusal`: not here."""
        if name not in NAMES:
            raise WorldRefusal(f"no condition {name!r} in contract {CONTRACT}; known: {', '.join(NAMES)}")
        if name not in self.conditions:
            raise WorldRefusal(
                "the server has no wrist (start it with --cougar sim)"
                if self._server.wrist is None
                else "the server's Cougar is not in-process (start it with --cougar sim)"
            )
        if name == "panic-button":
            token = self.hold(WorldConditions(frozenset({WorldCondition.PANIC_BUTTON}), panic_delay=0.0))
            now = self._server.now()
            for session in self._server.sessions:
                session.arm.press_panic(at=now)
            return token
        if name == "wrist-force":
            # The sensor reads the reaction of what pushes the hand: push the opposite way.
            force, torque = _vector(args, "force"), _vector(args, "torque")
            push = HandLoad([-f for f in force], [-t for t in torque])
            return self.hold(WorldConditions(), push)
        return self.hold(_world(name, args))

    def clear(self, token: int) -> bool:
        """Take an arrangement out; False when ``token`` is not held."""
        if self._held.pop(token, None) is None:
            return False
        self._apply()
        return True

    def clear_all(self) -> None:
        self._held.clear()
        self._apply()

    def _apply(self) -> None:
        world = self._base.faults.world
        hand: HandLoad | None = None
        for held in self._held.values():
            world = world.merged(held.world)
            hand = held.hand or hand
        self._server.config = replace(self._base, faults=replace(self._base.faults, world=world))
        load = getattr(self._server.wrist, "load_hand", None)
        if load is not None:
            load(hand)


def _world(name: str, args: Mapping[str, Any]) -> WorldConditions:
    """The world of a condition that connections meet from their start."""
    match name:
        case "obstacle":
            lower, upper = _optional(args, "lower"), _optional(args, "upper")
            if lower is None and upper is None:
                raise ValueError("an obstacle needs a lower or an upper bound")
            return WorldConditions(
                frozenset({WorldCondition.OBSTACLE}), obstacle=Obstacle(_joint(args), lower, upper)
            )
        case "calibration-failure":
            joints = args.get("joints", [2, 3])
            if not isinstance(joints, list) or not joints:
                raise ValueError(f"joints must be a non-empty array, not {joints!r}")
            picked = tuple(_joint({"joint": j}) for j in joints)
            return WorldConditions(frozenset({WorldCondition.CALIBRATE_NZI}), nzi_joints=picked)
        case "sluggish-joint":
            lag = _number(args.get("lag", 0.35), "lag")
            sluggish = Sluggish(_joint(args, default=2), lag)
            return WorldConditions(frozenset({WorldCondition.SLUGGISH_JOINT}), sluggish=sluggish)
    return WorldConditions(frozenset({WorldCondition.WRIST_SILENT}))


# ------------------------------------------------------------------------------------------ contract 2


def _line(message: Mapping[str, Any]) -> bytes:
    return (json.dumps(message, separators=(", ", ": ")) + "\n").encode()


class WorldServer:
    """A running :func:`serve_world`: ``address`` is where it listens (``tcp://HOST:PORT``)."""

    def __init__(self, world: ReferenceWorld, server: asyncio.Server) -> None:
        self.world = world
        self._server = server
        self._busy = asyncio.Lock()
        host, port = server.sockets[0].getsockname()[:2]
        self.address = f"tcp://[{host}]:{port}" if ":" in host else f"tcp://{host}:{port}"

    async def handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        """Serve one suite: hello, then answers, until it leaves; its arrangements are cleared then."""
        peer = writer.get_extra_info("peername")
        if self._busy.locked():
            writer.write(_line({"type": "busy", "contract": CONTRACT, "reason": "another suite is served"}))
            with contextlib.suppress(OSError):
                await writer.drain()
            writer.close()
            return
        async with self._busy:
            log.info("world: suite %s connected", peer)
            held: dict[int, int] = {}
            # the world's token of each arrangement held, by the id of its arrange message
            try:
                writer.write(_line(self.hello()))
                await writer.drain()
                while (message := await _read(reader)) is not None:
                    writer.write(_line(self.answer(message, held)))
                    await writer.drain()
            except (OSError, ValueError, TimeoutError) as exc:
                log.info("world: suite %s dropped: %s", peer, exc)
            finally:
                for token in held.values():
                    self.world.clear(token)
                writer.close()
                log.info("world: suite %s gone; %d arrangement(s) cleared", peer, len(held))

    def hello(self) -> dict[str, Any]:
        return {
            "type": "hello",
            "contract": CONTRACT,
            "name": "manip-server",
            "version": __version__,
            "conditions": list(self.world.conditions),
        }

    def answer(self, message: object, held: dict[int, int]) -> dict[str, Any]:
        """The one answer to one message of the suite."""
        if not isinstance(message, dict) or not isinstance(message.get("id"), int):
            return {"type": "failed", "id": None, "reason": "a message is an object with an integer id"}
        ident: int = message["id"]
        kind = message.get("type")
        if kind == "arrange":
            args = message.get("args", {})
            try:
                if not isinstance(args, dict):
                    raise ValueError("args must be an object")
                token = self.world.arrange(str(message.get("condition")), args)
            except WorldRefusal as exc:
                return {"type": "unsupported", "id": ident, "reason": str(exc)}
            except ValueError as exc:
                return {"type": "failed", "id": ident, "reason": str(exc)}
            held[ident] = token
            log.info("world: arranged %s %s (#%d)", message.get("condition"), json.dumps(args), ident)
            return {"type": "arranged", "id": ident}
        if kind == "clear":
            which = message.get("arrangement")
            if not isinstance(which, int) or which not in held:
                return {"type": "failed", "id": ident, "reason": f"no arrangement {which!r} is held"}
            self.world.clear(held.pop(which))
            log.info("world: cleared #%d", which)
            return {"type": "cleared", "id": ident}
        return {"type": "failed", "id": ident, "reason": f"unknown message type {kind!r}"}

    def close(self) -> None:
        self._server.close()


async def _read(reader: asyncio.StreamReader) -> object | None:
    """The next message of the suite (None at its end); ValueError for a line too long or not JSON."""
    async with asyncio.timeout(IDLE_TIMEOUT):
        try:
            raw = await reader.readuntil(b"\n")
        except asyncio.IncompleteReadError as exc:
            if exc.partial.strip():
                raise ValueError("the suite's last line has no newline") from None
            return None
        except asyncio.LimitOverrunError:
            raise ValueError(f"a line longer than {MAX_LINE} bytes") from None
    try:
        message: object = json.loads(raw)
    except ValueError:
        raise ValueError(f"not JSON: {raw[:80]!r}") from None
    return message


@contextlib.asynccontextmanager
async def serve_world(world: ReferenceWorld, address: str) -> AsyncIterator[WorldServer]:
    """Serve ``world`` on ``address`` (``tcp://HOST:PORT``; port 0 picks a free one) for the block."""
    parsed = parse_address(address)
    if parsed.scheme != "tcp":
        raise ValueError(f"the world listens on tcp://HOST:PORT, not {address!r}")
    holder: list[WorldServer] = []

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await holder[0].handle(reader, writer)

    server = await asyncio.start_server(handle, parsed.host, parsed.port, limit=MAX_LINE)
    holder.append(WorldServer(world, server))
    try:
        yield holder[0]
    finally:
        server.close()
        world.clear_all()
