"""The fake arm of the client tests (:mod:`tests.support.fake_arm`) answers as it claims to."""

from __future__ import annotations

from manip.spec.constants import RequestOp
from tests.support.fake_arm import HERE, run, session


def test_fake_answers_here_with_the_canned_transform() -> None:
    async def main() -> None:
        async with session() as (arm, fake):
            assert (await arm.here()).almost_equal(HERE, 1e-3)
            assert fake.peer.received[0].opcode == RequestOp.HERE

    run(main())


def test_fake_reports_unknown_opcodes_as_command_errors() -> None:
    async def main() -> None:
        async with session() as (arm, _):
            from manip.reference_client import NonFatalError

            arm.registry = arm.registry.copy()
            arm.registry.define_request_code("mystery", 0o230)
            try:
                await arm.request("mystery")
            except NonFatalError as err:
                assert (err.severity, err.code, err.message) == ("C", "UOP", "Unknown opcode 152")
            else:
                raise AssertionError("no error")

    run(main())
