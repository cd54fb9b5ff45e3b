"""Every command checks its options before anything runs: non-finite numbers, empty commands and
addresses that cannot be used are usage errors (exit 2) with a message, never a traceback."""

from __future__ import annotations

from collections.abc import Iterator

import click
import pytest
from click.testing import CliRunner

from manip.captures.cli import main as capture_main
from manip.commandline import CommandLine, FiniteFloat, LinkAddressType, check_host
from manip.conformance.cli import main as conform_main
from manip.cougar.cli import main as cougar_main
from manip.decode.cli import main as decode_main
from manip.links import parse_address
from manip.reference_client.cli import main as client_main
from manip.reference_server.cli import main as server_main
from tests.support.paths import ROOT

MAINS: dict[str, click.Command] = {
    "manip-capture": capture_main,
    "manip-conform": conform_main,
    "manip-cougar": cougar_main,
    "manip-decode": decode_main,
    "manip-client": client_main,
    "manip-server": server_main,
}


def _commands(name: str, command: click.Command) -> Iterator[tuple[str, click.Command]]:
    yield name, command
    if isinstance(command, click.Group):
        for sub_name, sub in command.commands.items():
            yield from _commands(f"{name} {sub_name}", sub)


def _float_params() -> list[tuple[str, click.Parameter]]:
    found = []
    for prog, main in MAINS.items():
        for name, command in _commands(prog, main):
            for param in command.params:
                if isinstance(param.type, click.FloatRange) or param.type is click.FLOAT:
                    found.append((f"{name} {param.name}", param))
    return found


FLOATS = _float_params()


def test_every_number_of_every_command_is_a_finite_float() -> None:
    assert len(FLOATS) > 20  # the walk finds the commands' options
    plain = [name for name, param in FLOATS if not isinstance(param.type, FiniteFloat)]
    assert not plain, f"float parameters that take nan and inf: {plain}"


@pytest.mark.parametrize(("name", "param"), FLOATS, ids=[name for name, _ in FLOATS])
@pytest.mark.parametrize("text", ["nan", "inf", "-inf", "NaN"])
def test_a_non_finite_number_is_refused(name: str, param: click.Parameter, text: str) -> None:
    with pytest.raises(click.BadParameter, match="not a finite number"):
        param.type.convert(text, param, None)


@pytest.mark.parametrize(
    ("main", "args", "says"),
    [
        (server_main, ["--frame-timeout", "nan"], "not a finite number"),
        (server_main, ["--broken-after", "inf"], "not a finite number"),
        (server_main, ["--listen", "tcp://300.1.1.1:0"], "not an IP address"),
        (server_main, ["--cougar", "tcp://300.1.1.1:1"], "not an IP address"),
        (cougar_main, ["--surface", "nan,nan,nan"], "finite"),
        (cougar_main, ["--listen", "tcp://300.1.1.1:1"], "not an IP address"),
        (conform_main, ["fuzz", "--launch", ""], "the command is empty"),
        (conform_main, ["fuzz", "--launch", "'unclosed"], "not a command line"),
        (
            conform_main,
            ["replay", str(ROOT / "captures" / "motion.mcap"), "--serve", "tcp://300.1.1.1:0"],
            "not an IP address",
        ),
        (conform_main, ["run", "--reply-timeout", "inf"], "not a finite number"),
        (client_main, ["tcp://127.0.0.1:9", "move-joints", "nan", "0", "0", "0", "0", "0"], "not a finite"),
        (client_main, ["tcp://127.0.0.1:9", "set-weight", "nan", "0", "0", "0"], "not a finite number"),
        (
            capture_main,
            ["record", "--listen", "tcp://300.1.1.1:1", "--upstream", "127.0.0.1:9", "-o", "x"],
            "IP",
        ),
    ],
)
def test_bad_options_are_usage_errors_before_anything_runs(
    main: click.Command, args: list[str], says: str
) -> None:
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2, result.output
    assert says in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)


def test_the_shared_types() -> None:
    assert FiniteFloat(min=0.0).convert("1.5", None, None) == 1.5
    with pytest.raises(click.BadParameter):
        FiniteFloat(min=0.0).convert("-1", None, None)
    assert LinkAddressType(parse_address).convert("tcp://127.0.0.1:0", None, None) == "tcp://127.0.0.1:0"
    with pytest.raises(click.BadParameter, match="chudp://"):
        LinkAddressType(parse_address, "chudp", ("chudp",)).convert("tcp://127.0.0.1:0", None, None)
    with pytest.raises(click.BadParameter, match="empty"):
        CommandLine().convert("   ", None, None)
    assert check_host("127.0.0.1") is None and check_host("::1") is None
    assert check_host("300.1.1.1") == "'300.1.1.1' is not an IP address"
