"""``manip-client URL COMMAND [ARGS]``: talk to a manipulator server from a terminal.

URL is a link address (``tcp://127.0.0.1:42085``, ``chudp://HOST:PORT?addr=440``, ``chaosd:///PATH``).
Output is aligned text in millimetres and degrees; ``--json`` prints one JSON object per result (per
event for ``watch``) instead, and a failure as one JSON object on stdout too (``error``, ``where``,
``severity``, ``code``, ``message``, ``args``, ``exit``; see :func:`~.cli_output.failure_record`) with the
same exit status.  Commands::

    describe                     what the server says about itself
    here                         where the hand is (x y z O A T, and the transform)
    joints                       the joint angles
    move-joints Q1 .. Q6 [--wait] [--power]  move to joint angles (degrees); prints the segment
    ready [--wait] [--power]     move to the ready position
    power on|off                 enable or kill arm power
    speed F                      set the speed factor, 0 < F <= 1
    solve-forwards X Y Z O A T | N1 .. P3 (12 floats) [--current Q1 .. Q6]
                                 joint angles reaching a pose (near the current joints by default)
    solve-backwards Q1 .. Q6     the pose of joint angles
    watch [--count N] [--seconds S]  print asynchronous responses, errors and warnings as they come
                                 (saying on stderr what it waits for)
    raw OPCODE [HEX] [--no-check]  send any request: opcode in octal, data bytes in wire order (hex);
                                 prints whatever comes back, decoded where the spec knows the opcode
    read-forces, read-raw-gauges, set-gauge-offsets, calibrate-wrist, set-spring, set-damping,
    set-joint-damping, set-frame-vector, set-weight, set-guard, clear-guard, compliant-move
                                 the wrist opcodes 0240-0253, arguments and help from the spec's
                                 layouts; ``--no-check`` sends malformed ones (wrong length, values
                                 out of range) for testing a server

``--record FILE`` writes the session's packets, both ways, to an MCAP capture (:mod:`manip.captures`;
``manip-capture info FILE`` lists it) with the command line in its metadata.  The file is closed, and
valid, however the command ends: success, an error, a lost connection or Ctrl-C; if it cannot be written
(a full disk), the command says so and exits 2.

Exit status: 0 success (``watch`` also when stopped with Ctrl-C); 1 the server answered with an error
(or a reply the client could not read, or one past ``--max-reply``); 2 usage (bad arguments, bad URL, a
``--record`` file that cannot be created or written); 3 cannot connect, or the connection was lost; 4 no
reply within ``--timeout``; 130 interrupted.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import sys
from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Final, NoReturn

import click

from manip.arm.oat import transform_from_xyzoat
from manip.arm.transform import Transform
from manip.codecs.messages import AsyncResponse
from manip.commandline import FINITE, FiniteFloat, configure_logging, version_option
from manip.exit_status import epilog
from manip.reference_client.cli_output import (
    async_record,
    async_text,
    describe_record,
    describe_text,
    dumps,
    error_line,
    failure_record,
    joints_record,
    joints_text,
    report_record,
    report_text,
    transform_record,
    transform_text,
)
from manip.reference_client.cli_requests import (
    WRIST_OPCODES,
    check_raw_data,
    encode_arguments,
    extract_raw,
    parse_hex,
    parse_opcode,
    raw_code,
    reply_record,
    reply_text,
    wrist_help,
    wrist_metavar,
)
from manip.reference_client.connect import aconnect
from manip.reference_client.errors import ConnectionLostError, ManipError, RequestTimeout
from manip.reference_client.harness import main as harness_main
from manip.reference_client.manipulator import NOTIFY_GUARD_HITS, NOTIFY_SEGMENTS, Manipulator
from manip.reference_client.options import DEFAULT_MAX_REPLY_BYTES, ClientOptions
from manip.spec import RequestOpcode

if TYPE_CHECKING:
    from manip.captures import Recorder
    from manip.links.api import LinkWrapper

PROG: Final = "manip-client"
EXIT_SERVER_ERROR: Final = 1
EXIT_USAGE: Final = 2
EXIT_CONNECTION: Final = 3
EXIT_TIMEOUT: Final = 4
EXIT_INTERRUPTED: Final = 130
DEFAULT_TIMEOUT: Final = 10.0

NUMBERS: Final = {"ignore_unknown_options": True}
"""Lets negative numbers through as arguments (``move-joints 0 -90 90 0 0 0``)."""


def _common_options(command: Callable[..., None]) -> Callable[..., None]:
    """--json, --timeout, --contact and --record: accepted before URL, between URL and COMMAND, and
    after COMMAND."""
    command = click.option(
        "--record",
        type=click.Path(dir_okay=False, writable=True),
        default=None,
        metavar="FILE",
        help="Record the session's packets, both ways, to an MCAP capture FILE (see manip-capture).",
    )(command)
    command = click.option(
        "--contact", default=None, help="Chaos contact name (default: the URL's, else PUMA)."
    )(command)
    command = click.option(
        "--max-reply",
        type=click.IntRange(min=1),
        default=None,
        metavar="BYTES",
        help="Give up a reply (and the connection) past this many data bytes "
        f"(default {DEFAULT_MAX_REPLY_BYTES}).",
    )(command)
    command = click.option(
        "--timeout",
        type=FiniteFloat(min=0.0, min_open=True),
        default=None,
        help=f"Seconds to wait for the connection and for each reply (default {DEFAULT_TIMEOUT:g}).",
    )(command)
    return click.option(
        "--json", "as_json", is_flag=True, default=None, help="One JSON object per result instead of text."
    )(command)


@dataclass(frozen=True)
class Settings:
    url: str
    as_json: bool
    timeout: float
    contact: str | None
    record: str | None = None
    command_line: tuple[str, ...] = ()
    """What the capture's metadata says was run."""
    max_reply: int = DEFAULT_MAX_REPLY_BYTES

    def overridden(
        self,
        as_json: bool | None,
        timeout: float | None,
        contact: str | None,
        record: str | None,
        max_reply: int | None = None,
    ) -> Settings:
        return replace(
            self,
            as_json=self.as_json if not as_json else True,
            timeout=self.timeout if timeout is None else timeout,
            contact=self.contact if contact is None else contact,
            record=self.record if record is None else record,
            max_reply=self.max_reply if max_reply is None else max_reply,
        )

    def options(self, wrap_link: LinkWrapper | None = None) -> ClientOptions:
        return ClientOptions(
            timeout=self.timeout,
            connect_timeout=self.timeout,
            contact=self.contact,
            name=PROG,
            wrap_link=wrap_link,
            max_reply_bytes=self.max_reply,
        )

    def recorder(self) -> tuple[Recorder, LinkWrapper] | None:
        """The ``--record`` capture, opened (call inside the running loop: its timer flushes it while
        the session is idle), and the link wrapper that records into it."""
        if self.record is None:
            return None
        # Imported here: the capture library (mcap, zstd: ~0.1 s) loads only when recording.
        from manip.captures import CaptureError, Recorder, RecorderTap  # noqa: PLC0415

        try:
            recorder = Recorder(self.record, how="client", command_line=self.command_line)
        except CaptureError as exc:
            raise RecordError(str(exc)) from exc
        return recorder, RecorderTap(recorder, "client").wrap

    def show(self, record: Mapping[str, Any], lines: Sequence[str]) -> None:
        if self.as_json:
            click.echo(dumps(record))
        else:
            for line in lines:
                click.echo(line)


Action = Callable[[Manipulator], Awaitable[None]]


class RecordError(Exception):
    """The ``--record`` file cannot be created, or could not be written (a full disk)."""


def _fail(error: BaseException, code: int, as_json: bool = False) -> NoReturn:
    """One line on stderr, or with ``--json`` one JSON object on stdout (where the results go), then
    exit with ``code``."""
    if as_json:
        kind = {EXIT_USAGE: "usage", EXIT_INTERRUPTED: "interrupted"}.get(code)
        click.echo(dumps(failure_record(error, code, kind=kind)))
    else:
        click.echo(f"{PROG}: {error_line(error)}", err=True)
    sys.exit(code)


class InterruptError(Exception):
    """Ctrl-C during a command that it does not end cleanly."""

    def __str__(self) -> str:
        return "interrupted"


def _run(settings: Settings, action: Action, *, interrupt_ends: bool = False) -> None:
    """Connect, run ``action``, disconnect; turn every failure into one line and an exit status."""

    async def session() -> None:
        recording = settings.recorder()
        if recording is None:
            async with aconnect(settings.url, settings.options()) as arm:
                await action(arm)
            return
        recorder, wrap_link = recording
        done = False
        try:
            async with aconnect(settings.url, settings.options(wrap_link)) as arm:
                await action(arm)
            done = True
        finally:  # also on Ctrl-C: asyncio.run cancels this task before raising KeyboardInterrupt
            recorder.close()
            error = recorder.write_error  # the file could not be written (a full disk)
            if error is not None:
                unwritten.append(RecordError(str(error)))
                if not done:  # the command's own failure is said next; say this one too
                    click.echo(f"{PROG}: {error}", err=True)

    as_json = settings.as_json
    unwritten: list[RecordError] = []
    try:
        asyncio.run(session())
        if unwritten:  # the command did its work, but its recording is lost: a --record problem
            _fail(unwritten[0], EXIT_USAGE, as_json)
    except KeyboardInterrupt:
        if not interrupt_ends:
            _fail(InterruptError(), EXIT_INTERRUPTED, as_json)
    except RequestTimeout as exc:
        _fail(exc, EXIT_TIMEOUT, as_json)
    except ConnectionLostError as exc:
        _fail(exc, EXIT_CONNECTION, as_json)
    except ManipError as exc:
        _fail(exc, EXIT_SERVER_ERROR, as_json)
    except (ValueError, RecordError) as exc:  # argument checks, an unparsable URL (AddressError)
        _fail(exc, EXIT_USAGE, as_json)


HELP: Final = """Talk to a manipulator server at URL (tcp://HOST:PORT, chudp://HOST:PORT?addr=OCTAL,
chaosd:///PATH).  Text in mm and degrees by default, --json for scripts (failures too: one JSON object
on stdout).  raw sends any opcode; the wrist opcodes 0240-0253 are commands; --no-check sends malformed
requests.  ``manip-client harness`` (no URL) is the client's harness for ``manip-conform client``
(docs/client-harness.md).

""" + epilog("manip-client")


_FLAGS: Final = frozenset({"--json", "-h", "--help"})
_VALUED: Final = frozenset({"--timeout", "--contact", "--record", "--max-reply"})


def _options_first(args: list[str]) -> list[str]:
    """Move the common options written between URL and COMMAND in front of URL, where click wants
    them: ``URL --json here`` is read as ``--json URL here``."""
    i = 0
    while i < len(args) and args[i].startswith("-"):  # options already before URL
        i += 2 if args[i] in _VALUED else 1
    if i >= len(args):
        return args
    moved: list[str] = []
    j = i + 1
    while j < len(args) and args[j].startswith("-"):
        name = args[j].split("=", 1)[0]
        if name in _FLAGS or (name in _VALUED and "=" in args[j]):
            moved.append(args[j])
            j += 1
        elif name in _VALUED and j + 1 < len(args):
            moved += args[j : j + 2]
            j += 2
        else:
            break
    return [*args[:i], *moved, args[i], *args[j:]]


class _ClientGroup(click.Group):
    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        if args[:1] == ["harness"]:  # ``manip-client harness``: no URL, the suite gives one per case
            ctx.exit(harness_main(args[1:], prog=f"{PROG} harness"))
        ctx.meta["manip.argv"] = (PROG, *args)  # as given, for a capture's metadata
        return super().parse_args(ctx, _options_first(args))


@click.group(cls=_ClientGroup, context_settings={"help_option_names": ["-h", "--help"]}, help=HELP)
@click.argument("url")
@_common_options
@version_option(PROG)
@click.pass_context
def main(
    ctx: click.Context,
    url: str,
    as_json: bool | None,
    timeout: float | None,
    contact: str | None,
    record: str | None,
    max_reply: int | None,
) -> None:
    configure_logging(logging.ERROR)  # a failure is this command's one line: the library's warnings repeat it
    ctx.obj = Settings(
        url,
        bool(as_json),
        DEFAULT_TIMEOUT if timeout is None else timeout,
        contact,
        record,
        tuple(ctx.meta.get("manip.argv", (PROG, *sys.argv[1:]))),
        DEFAULT_MAX_REPLY_BYTES if max_reply is None else max_reply,
    )


def pass_settings(command: Callable[..., None]) -> Callable[..., None]:
    """Give the command the group's settings, overridden by the common options given after it."""

    def wrapper(
        ctx: click.Context,
        *args: Any,
        as_json: bool | None,
        timeout: float | None,
        contact: str | None,
        record: str | None,
        max_reply: int | None,
        **kwargs: Any,
    ) -> None:
        settings = ctx.find_object(Settings)
        assert settings is not None
        settings = settings.overridden(as_json, timeout, contact, record, max_reply)
        command(settings, *args, **kwargs)

    functools.update_wrapper(wrapper, command)  # the docstring is the command's help
    return _common_options(click.pass_context(wrapper))


# ------------------------------------------------------------------ queries


@main.command()
@pass_settings
def describe(settings: Settings) -> None:
    """What the server says about itself (describe self, 0200)."""

    async def action(arm: Manipulator) -> None:
        alist = await arm.describe()
        settings.show(describe_record(alist), describe_text(alist))

    _run(settings, action)


@main.command()
@pass_settings
def here(settings: Settings) -> None:
    """Where the hand is (0201)."""

    async def action(arm: Manipulator) -> None:
        pose = await arm.here()
        settings.show(transform_record(pose), transform_text(pose))

    _run(settings, action)


@main.command()
@pass_settings
def joints(settings: Settings) -> None:
    """The joint angles, degrees (0202)."""

    async def action(arm: Manipulator) -> None:
        q = await arm.joint_angles()
        settings.show(joints_record(q), joints_text(q))

    _run(settings, action)


# ------------------------------------------------------------------ motion and settings


async def _motion(
    arm: Manipulator, settings: Settings, start: Callable[[], Awaitable[int]], wait: bool, power: bool
) -> None:
    if power:
        await arm.enable_power()
    if wait:
        await arm.prepare_segment_wait()  # notifications, or polling on a server without them
    segment = await start()
    if wait:
        await arm.wait_for_segment(segment)
    state = "completed" if wait else "queued"
    settings.show({"segment": segment, "completed": wait}, [f"segment {segment} {state}"])


_WAIT = click.option("--wait", is_flag=True, help="Wait until the motion has completed.")
_POWER = click.option(
    "--power",
    is_flag=True,
    help="Enable arm power first (a server may start each connection with the power off).",
)


@main.command("move-joints", context_settings=NUMBERS)
@click.argument("q", nargs=6, type=FINITE, metavar="Q1 Q2 Q3 Q4 Q5 Q6")
@_WAIT
@_POWER
@pass_settings
def move_joints(settings: Settings, q: tuple[float, ...], wait: bool, power: bool) -> None:
    """Move to joint angles in degrees (set joint angles, 0215)."""

    async def action(arm: Manipulator) -> None:
        await _motion(arm, settings, lambda: arm.set_joint_angles(q), wait, power)

    _run(settings, action)


@main.command()
@_WAIT
@_POWER
@pass_settings
def ready(settings: Settings, wait: bool, power: bool) -> None:
    """Move to the ready position (0214)."""

    async def action(arm: Manipulator) -> None:
        await _motion(arm, settings, arm.ready, wait, power)

    _run(settings, action)


@main.command()
@click.argument("state", type=click.Choice(["on", "off"]))
@pass_settings
def power(settings: Settings, state: str) -> None:
    """Enable (0217) or kill (0206) arm power."""

    async def action(arm: Manipulator) -> None:
        await (arm.enable_power() if state == "on" else arm.kill_power())
        settings.show({"power": state}, [f"arm power {state}"])

    _run(settings, action)


@main.command()
@click.argument("factor", type=FINITE)
@pass_settings
def speed(settings: Settings, factor: float) -> None:
    """Set the speed factor, 0 < FACTOR <= 1 (0216)."""

    async def action(arm: Manipulator) -> None:
        await arm.set_speed(factor)
        settings.show({"speed": factor}, [f"speed factor {factor:g}"])

    _run(settings, action)


# ------------------------------------------------------------------ kinematics


def _pose(values: Sequence[float]) -> Transform:
    try:
        if len(values) == 6:
            return transform_from_xyzoat(*values)
        if len(values) == 12:
            return Transform.from_floats(values)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="POSE") from exc
    raise click.UsageError(
        f"give 6 numbers (x y z O A T) or 12 (a transform, column major), not {len(values)}"
    )


@main.command("solve-forwards", context_settings=NUMBERS)
@click.argument("pose", nargs=-1, type=FINITE, metavar="X Y Z O A T | N1 N2 N3 O1 O2 O3 A1 A2 A3 P1 P2 P3")
@click.option(
    "--current",
    nargs=6,
    type=FINITE,
    default=None,
    metavar="Q1 .. Q6",
    help="Joint angles to choose the solution near (default: where the arm is).",
)
@pass_settings
def solve_forwards(settings: Settings, pose: tuple[float, ...], current: tuple[float, ...] | None) -> None:
    """The joint angles that reach a pose (solve forwards, 0220)."""
    target = _pose(pose)

    async def action(arm: Manipulator) -> None:
        near = current if current is not None else await arm.joint_angles()
        q = await arm.solve_forwards(target, near)
        settings.show(joints_record(q), joints_text(q))

    _run(settings, action)


@main.command("solve-backwards", context_settings=NUMBERS)
@click.argument("q", nargs=6, type=FINITE, metavar="Q1 Q2 Q3 Q4 Q5 Q6")
@pass_settings
def solve_backwards(settings: Settings, q: tuple[float, ...]) -> None:
    """The pose of joint angles (solve backwards, 0221)."""

    async def action(arm: Manipulator) -> None:
        pose = await arm.solve_backwards(q)
        settings.show(transform_record(pose), transform_text(pose))

    _run(settings, action)


# ------------------------------------------------------------------ watch


def _waiting_for(url: str, count: int | None, seconds: float | None, guards: bool) -> str:
    """What ``watch`` says on stderr once it listens: what it waits for and what ends it."""
    kinds = "segment completions" + (" and guard hits" if guards else "")
    ends = ["Ctrl-C"]
    if count is not None:
        ends.append(f"{count} response{'s' if count != 1 else ''}")
    if seconds is not None:
        ends.append(f"{seconds:g} s")
    return f"waiting for {kinds}, asynchronous errors and warnings from {url} (until {' or '.join(ends)})"


@main.command()
@click.option(
    "--count", type=click.IntRange(min=1), default=None, help="Stop after N asynchronous responses."
)
@click.option("--seconds", type=FiniteFloat(min=0.0), default=None, help="Stop after S seconds.")
@click.option("--guards/--no-guards", default=True, show_default=True, help="Ask for guard hits too.")
@pass_settings
def watch(settings: Settings, count: int | None, seconds: float | None, guards: bool) -> None:
    """Print asynchronous responses (and asynchronous errors and warnings) as they come, until
    Ctrl-C, --count or --seconds."""

    def show_response(response: AsyncResponse) -> None:
        settings.show(async_record(response), [async_text(response)])

    def show_report(error: ManipError) -> None:
        settings.show(report_record(error), [report_text(error)])

    async def action(arm: Manipulator) -> None:
        arm.add_error_listener(show_report)
        loop = asyncio.get_running_loop()
        deadline = None if seconds is None else loop.time() + seconds
        async with arm.async_responses() as stream:
            await arm.request_notifications(NOTIFY_SEGMENTS | (NOTIFY_GUARD_HITS if guards else 0))
            click.echo(f"{PROG}: {_waiting_for(settings.url, count, seconds, guards)}", err=True)
            seen = 0
            while count is None or seen < count:
                remaining = None if deadline is None else max(0.0, deadline - loop.time())
                try:
                    response = await asyncio.wait_for(anext(stream), remaining)
                except (TimeoutError, StopAsyncIteration):
                    break
                show_response(response)
                seen += 1

    _run(settings, action, interrupt_ends=True)


# ------------------------------------------------------------------ by opcode: raw and the wrist

_NO_CHECK = click.option(
    "--no-check",
    is_flag=True,
    help="Send what was typed even if the request is malformed (wrong length, out-of-range values): "
    "for testing a server.",
)


def _send_by_opcode(settings: Settings, opcode: int, data: bytes) -> None:
    """Send ``data`` with ``opcode`` and show whatever comes back (an error reply is a failure)."""
    code, response_type = raw_code(opcode, data)

    async def action(arm: Manipulator) -> None:
        request = arm.make_request(code, data, response_type=response_type, extractor=extract_raw)
        reply = await arm.send_request(request)
        settings.show(reply_record(reply), reply_text(reply))

    _run(settings, action)


@main.command(context_settings=NUMBERS)
@click.argument("opcode")
@click.argument("data", nargs=-1, metavar="[HEX]")
@_NO_CHECK
@pass_settings
def raw(settings: Settings, opcode: str, data: tuple[str, ...], no_check: bool) -> None:
    """Send a request by OPCODE (octal, 0200-0277) with HEX data bytes in wire order ("3f 80 00 00"
    or 3f800000; none: no data), and show whatever comes back, decoded where the spec knows the opcode.

    The data of an opcode the spec defines must fit its layout (length, floats) unless --no-check,
    which also allows any data opcode up to 0377.
    """
    try:
        number = parse_opcode(opcode, no_check=no_check)
        payload = parse_hex(data)
        if not no_check:
            check_raw_data(number, payload)
    except ValueError as exc:
        _fail(exc, EXIT_USAGE, settings.as_json)
    _send_by_opcode(settings, number, payload)


def _wrist_command(op: RequestOpcode) -> None:
    """Add ``op``'s command, its arguments and help taken from the spec."""

    def command(settings: Settings, values: tuple[str, ...], no_check: bool) -> None:
        try:
            payload = encode_arguments(op, values, no_check=no_check)
        except ValueError as exc:
            _fail(exc, EXIT_USAGE, settings.as_json)
        _send_by_opcode(settings, op.opcode, payload)

    command.__name__ = op.name.replace("-", "_")
    command.__doc__ = wrist_help(op)
    decorated = pass_settings(_NO_CHECK(command))
    # No fields: values are for --no-check only (a request that should carry no data).
    metavar = wrist_metavar(op) or "[VALUES]"
    decorated = click.argument("values", nargs=-1, metavar=metavar)(decorated)
    main.command(op.name, context_settings=NUMBERS)(decorated)


for _op in WRIST_OPCODES:
    _wrist_command(_op)


if __name__ == "__main__":  # pragma: no cover
    main()
