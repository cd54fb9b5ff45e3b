"""The README's examples work: every ``manip-*`` command line parses with the command it names (an
option renamed or dropped breaks this test, not a reader's first try; the commands' bodies are replaced),
and the client example runs against a reference server."""

from __future__ import annotations

import asyncio
import itertools
import re
import shlex
from importlib.metadata import entry_points
from pathlib import Path

import click
import pytest

from tests.support.paths import ROOT

COMMANDS = {e.name: e for e in entry_points(group="console_scripts") if e.name.startswith("manip-")}


def readme_command_lines() -> list[str]:
    """Command lines of the README's ``sh`` blocks, comments cut, ``a|b`` shorthand spelt out."""
    text = (ROOT / "README.md").read_text()
    lines: list[str] = []
    for block in re.findall(r"```sh\n(.*?)```", text, re.S):
        for raw in block.splitlines():
            line = raw.split("  #")[0].strip()
            if not line.startswith("manip-"):
                continue
            words = shlex.split(line)
            choices = [word.split("|") if "|" in word else [word] for word in words]
            lines += [shlex.join(variant) for variant in itertools.product(*choices)]
    return lines


LINES = readme_command_lines()


def test_the_readme_shows_every_command() -> None:
    assert {shlex.split(line)[0] for line in LINES} == set(COMMANDS)


def _leaves(command: click.Command) -> list[click.Command]:
    if isinstance(command, click.Group):
        return [leaf for sub in command.commands.values() for leaf in _leaves(sub)]
    return [command]


@pytest.mark.parametrize("line", LINES)
def test_readme_command_line_parses(line: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    words = shlex.split(line)
    monkeypatch.chdir(tmp_path)
    for word in words:  # the files a line reads exist, empty (their content is not looked at)
        if re.fullmatch(r"[\w.-]+(/[\w.-]+)*\.(mcap|bin|json|pcap|pcapng)", word):
            (tmp_path / word).parent.mkdir(parents=True, exist_ok=True)
            (tmp_path / word).touch()
    command = COMMANDS[words[0]].load()
    ran: list[str] = []
    for leaf in _leaves(command):  # parsed as usual, then nothing done: no server, no connection
        monkeypatch.setattr(leaf, "callback", lambda *args, _name=leaf.name, **kwargs: ran.append(_name))
    command.main(words[1:], prog_name=words[0], standalone_mode=False)  # a usage error raises
    assert len(ran) == 1


def test_the_readme_client_example_runs(
    reference_server_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """The first Python example, as written, against a reference server (its address swapped in)."""
    text = (ROOT / "README.md").read_text()
    example = re.findall(r"```python\n(.*?)```", text, re.S)[0]
    assert "manip.connect(" in example and "async def main" in example
    namespace: dict[str, object] = {}
    source = example.replace("tcp://127.0.0.1:42085", reference_server_url)
    exec(compile(source, "README.md", "exec"), namespace)
    main = namespace["main"]
    assert callable(main)
    asyncio.run(main())
    shown = capsys.readouterr().out
    assert "Transform" in shown and ":" in shown  # here()'s transform, then describe()'s alist
