"""COMINT (the 1985 guide, B.7) in the simulator: buffering, chunking, out-of-sync recovery, decodable
output."""

from __future__ import annotations

import itertools
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from manip.codecs.cougar import CougarMsg, WordStream, encode
from manip.cougar import CougarConfig, CougarSim
from manip.cougar.comint import COMMANDS, Comint, Executable, OutOfSyncEvent
from manip.cougar.memory import region
from manip.spec import SPEC
from tests.support.strategies import cougar_values

# No gravity on the hand and no gauge offsets: every force reads zero, so answers do not depend on time.
QUIET = CougarConfig(hand_weight_oz=0.0)
words = st.integers(0, 0xFFFF)
SCRATCH = region("guards").address  # a region no command routine reads while no guard is armed


def responses(out: list[int]) -> list[CougarMsg]:
    stream = WordStream("response")
    items = stream.feed(out)
    assert stream.pending == ()
    assert all(isinstance(i, CougarMsg) for i in items), items
    return [i for i in items if isinstance(i, CougarMsg)]


def _command(name: str, values: dict[str, Any]) -> list[int]:
    return encode("command", name, **values)


def random_command() -> st.SearchStrategy[list[int]]:
    msgs = sorted(SPEC.cougar_commands.values(), key=lambda m: m.code)
    return st.sampled_from(msgs).flatmap(lambda m: cougar_values(m).map(lambda v: _command(m.name, v)))


@st.composite
def time_invariant_command(draw: st.DrawFn) -> list[int]:
    """Commands whose answers do not depend on which tick runs them (with QUIET, nothing armed)."""
    kind = draw(st.sampled_from(["NOP", "WINIT", "VERS", "EXMN", "DPST", "NFC", "NK", "NB", "RFRC", "RRAW"]))
    if kind == "EXMN":
        return _command(kind, {"address": SCRATCH, "count": draw(st.integers(0, 6))})
    if kind == "DPST":
        return _command(kind, {"address": SCRATCH + 2 * draw(st.integers(0, 5)), "value": draw(words)})
    msg = next(m for m in SPEC.cougar_commands.values() if m.name == kind)
    return _command(kind, draw(cougar_values(msg)))


def cuts(data: st.DataObject, n: int) -> list[int]:
    return sorted(set(data.draw(st.lists(st.integers(0, n), max_size=8))))


def pieces(stream: list[int], at: list[int]) -> list[list[int]]:
    bounds = [0, *at, len(stream)]
    return [stream[a:b] for a, b in itertools.pairwise(bounds)]


def test_table_lengths_are_the_spec_data() -> None:
    assert set(COMMANDS) == set(SPEC.cougar_commands)
    for code, entry in COMMANDS.items():
        assert entry.data_words == SPEC.cougar_commands[code].data_words
        assert entry.name == SPEC.cougar_commands[code].name


def test_partial_command_waits_for_the_rest() -> None:
    comint = Comint()
    vers = encode("command", "VERS", version=7)
    comint.receive(vers[:1])
    assert comint.take() is None
    comint.receive(vers[1:])
    item = comint.take()
    assert isinstance(item, Executable)
    assert item.entry.name == "VERS"
    assert item.data == (7,)
    assert comint.take() is None


def test_unknown_code_dumps_the_buffer() -> None:
    comint = Comint()
    comint.receive([0, 99, 13, 5])
    assert isinstance(comint.take(), Executable)  # the NOP before the bad word still runs
    item = comint.take()
    assert item == OutOfSyncEvent(99, (99, 13, 5))
    assert comint.pending == ()


@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_chunking_within_a_tick_never_changes_the_result(data: st.DataObject) -> None:
    parts = data.draw(st.lists(st.one_of(random_command(), st.lists(words, max_size=3)), max_size=6))
    stream = [w for p in parts for w in p]
    at = cuts(data, len(stream))
    whole, chunked = CougarSim(QUIET, seed=1), CougarSim(QUIET, seed=1)
    whole.receive(stream)
    for piece in pieces(stream, at):
        chunked.receive(piece)
    assert whole.tick(0.0) == chunked.tick(0.0)
    assert whole.pending == chunked.pending
    assert whole.memory.read_words(0, 0o10000) == chunked.memory.read_words(0, 0o10000)


@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_splitting_commands_across_ticks_never_changes_the_answers(data: st.DataObject) -> None:
    commands = data.draw(st.lists(time_invariant_command(), min_size=1, max_size=6))
    stream = [w for c in commands for w in c]
    at = cuts(data, len(stream))
    one = CougarSim(QUIET)
    one.receive(stream)
    expected = one.tick(0.0)
    split = CougarSim(QUIET)
    got: list[int] = []
    for i, piece in enumerate(pieces(stream, at)):
        split.receive(piece)
        got += split.tick(i * 1.0)
    got += split.tick(100.0)
    assert got == expected
    assert split.stats.commands == one.stats.commands == len(commands)
    assert split.stats.out_of_sync == 0


@settings(max_examples=40, deadline=None)
@given(
    before=st.lists(time_invariant_command(), max_size=3),
    bad=st.integers(len(COMMANDS), 0xFFFF),
    junk=st.lists(words, max_size=10),
    version=words,
)
def test_out_of_sync_recovers_at_the_next_valid_command(
    before: list[list[int]], bad: int, junk: list[int], version: int
) -> None:
    sim = CougarSim(QUIET)
    for c in before:
        sim.receive(c)
    sim.receive([bad, *junk])
    out = responses(sim.tick(0.0))
    assert [m.name for m in out].count("OUT-OF-SYNC") == 1
    assert out[-1].name == "OUT-OF-SYNC"
    assert out[-1].values["code"] == bad
    assert sim.pending == ()
    assert sim.stats.out_of_sync == 1
    assert sim.stats.discarded_words == 1 + len(junk)
    sim.receive(encode("command", "VERS", version=version))
    after = responses(sim.tick(1.0))
    assert [(m.name, m.values["version"]) for m in after] == [("VERSION", 1)]
    assert sim.memory.word("puma_version") == version


@settings(max_examples=60, deadline=None)
@given(stream=st.lists(st.one_of(random_command(), st.lists(words, max_size=4)), max_size=8))
def test_any_word_stream_gives_decodable_answers(stream: list[list[int]]) -> None:
    sim = CougarSim(QUIET, seed=3)
    out: list[int] = []
    for i, part in enumerate(stream):
        sim.receive(part)
        out += sim.tick(i * 0.1)
    responses(out)
    assert sim.stats.words_sent == len(out)
