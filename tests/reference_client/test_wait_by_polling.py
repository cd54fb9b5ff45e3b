"""Waiting for a motion on a server without manip's notifications extension (0257): the library and
``manip-client --wait`` fall back to the 1985 guide's own requests (polling Joint angles), and a refusal
of an extension opcode says that it is one.  Against the reference server with its extensions off."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator

import pytest

from manip.codecs.error_string import ErrorMessage
from manip.reference_client import aconnect
from manip.reference_client.cli import EXIT_SERVER_ERROR
from manip.reference_client.errors import AsynchronousError, NonFatalError, RequestTimeout
from manip.reference_client.manipulator import NOTIFY_SEGMENTS
from manip.reference_server import ServerConfig
from manip.spec.constants import RequestOp
from tests.support.client_cli import invoke
from tests.support.scripted import READY, TARGET
from tests.support.servers import in_thread, reference_server

pytestmark = pytest.mark.waits  # the polls are in the client's own (real) time

GUIDE_ONLY = ServerConfig(extensions=False)


@pytest.fixture(scope="module")
def guide_url() -> Iterator[str]:
    with in_thread(reference_server(GUIDE_ONLY)) as address:
        yield address


@pytest.fixture(scope="module")
def full_url() -> Iterator[str]:
    with in_thread(reference_server()) as address:
        yield address


def _close(a: tuple[float, ...], b: list[float]) -> bool:
    return all(abs(x - y) <= 1e-3 for x, y in zip(a, b, strict=True))


def test_wait_for_segment_polls_when_notifications_are_refused(guide_url: str) -> None:
    async def main() -> None:
        async with aconnect(guide_url) as arm:
            await arm.enable_power()
            first = await arm.set_joint_angles(TARGET)
            second = await arm.set_joint_angles(READY)
            await arm.wait_for_segment(first, timeout=30.0)  # 0257 refused as unknown: polls from here on
            assert arm.waits_by_polling and not arm.notifications & NOTIFY_SEGMENTS
            await arm.wait_for_segment(second, timeout=30.0)
            assert _close(tuple(await arm.joint_angles()), READY)
            assert arm.last_completed_segment == second

    asyncio.run(main())


def test_describe_self_without_0257_sends_waits_to_polling_at_once(guide_url: str) -> None:
    async def main() -> None:
        async with aconnect(guide_url) as arm:
            assert RequestOp.REQUEST_NOTIFICATIONS not in (await arm.describe())["operations"]  # type: ignore[operator]
            assert arm.waits_by_polling
            await arm.enable_power()
            segment = await arm.set_joint_angles(TARGET)
            await arm.wait_for_segment(segment, timeout=30.0)
            assert _close(tuple(await arm.joint_angles()), TARGET)

    asyncio.run(main())


def test_a_wait_by_polling_is_bounded(guide_url: str) -> None:
    async def main() -> None:
        async with aconnect(guide_url) as arm:
            await arm.enable_power()
            await arm.set_speed(0.01)  # slow enough to be still moving when the bound ends
            segment = await arm.set_joint_angles(TARGET)
            segment = await arm.set_joint_angles(READY)
            with pytest.raises(RequestTimeout, match=r"segment \d+ did not complete \(polled joint angles"):
                await arm.wait_for_segment(segment, timeout=0.2)
            await arm.kill_power()

    asyncio.run(main())


def test_an_abort_fails_a_wait_by_polling(guide_url: str) -> None:
    async def main() -> None:
        async with aconnect(guide_url) as arm:
            await arm.enable_power()
            await arm.set_speed(0.05)
            segment = await arm.set_joint_angles(TARGET)
            segment = await arm.set_joint_angles(READY)
            waiter = asyncio.create_task(arm.wait_for_segment(segment, timeout=30.0))
            await asyncio.sleep(0.2)
            await arm.kill_power()  # the move process aborts the running segment: an asynchronous error
            with pytest.raises(AsynchronousError):
                await waiter

    asyncio.run(main())


def test_a_server_with_notifications_is_not_polled(full_url: str) -> None:
    async def main() -> None:
        async with aconnect(full_url) as arm:
            await arm.enable_power()
            segment = await arm.set_joint_angles(TARGET)
            await arm.wait_for_segment(segment, timeout=30.0)
            assert not arm.waits_by_polling and arm.notifications & NOTIFY_SEGMENTS

    asyncio.run(main())


def test_the_refusal_of_an_extension_names_it(guide_url: str) -> None:
    async def main() -> None:
        async with aconnect(guide_url) as arm:
            with pytest.raises(NonFatalError) as refused:
                await arm.request_notifications(NOTIFY_SEGMENTS)
            assert refused.value.code == "UOP"
            assert refused.value.unserved_extension == "0257, request notifications, a Puma extension"
            assert "0257, request notifications, a Puma extension" in str(refused.value)

    asyncio.run(main())
    unknown = ErrorMessage("Command dispatch", "C", "UOP", "Unimplemented opcode ~.", (0o277,))
    assert NonFatalError(unknown, request_number=1).unserved_extension is None  # not manip's extension
    named = ErrorMessage("Command dispatch", "C", "UOP", "Unimplemented opcode ~.", (0o260,))
    assert NonFatalError(named, request_number=1).unserved_extension == "0260, reset abort, a Puma extension"


def test_manip_client_wait_on_a_guide_only_server(guide_url: str) -> None:
    result = invoke(guide_url, "move-joints", *map(str, TARGET), "--power", "--wait")
    assert result.exit_code == 0, result.output
    assert result.stdout.startswith("segment ") and "completed" in result.stdout
    joints = invoke(guide_url, "joints", "--json")
    assert joints.exit_code == 0, joints.output
    assert '"joints"' in joints.stdout


def test_manip_client_names_the_extension_it_was_refused(guide_url: str) -> None:
    result = invoke(guide_url, "watch", "--seconds", "0.1")
    assert result.exit_code == EXIT_SERVER_ERROR, result.output
    line = result.stderr.strip().splitlines()[-1]
    assert line.startswith("manip-client: UOP: ") and "0257, request notifications, a Puma extension" in line
