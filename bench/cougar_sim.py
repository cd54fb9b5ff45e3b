"""The simulated Cougar's cost per tick (issue 17), run by hand.

A Puma-like driver moves the arm along smooth joint-space segments with pauses, sending SEN with the
sensed angles every tick the arm moved (as the wrist output process does), RFRC every few ticks, RRAW
now and then, and NPR instead of SEN on a quarter of the segments (compliant ones); the tool touches a
surface and a spring, and the gauges have noise and cross-coupling (then again in free space with exact
gauges, the reference server's default).  Printed: CougarSim.tick calls per second of CPU time (process
time, so that other work on the machine counts less; best of ``--rounds``; an absolute figure, there is
no baseline to run beside it), then what one tick's parts cost, timed around each part, the kinematics'
cost per call, and a profile of the same loop.

    .venv/bin/python bench/cougar_sim.py [--ticks 3000] [--rounds 5] [--no-profile]
    .venv/bin/python bench/cougar_sim.py --digest [--ticks 600]

``--digest`` times nothing: it runs scripted sessions (the driver above plus every command of Table 1
with random and extreme values, deposits anywhere in the map and into θ_sensed behind SEN's back, ticks
that come too early, several configurations and faults) and prints a SHA-256 over every word Cougar
sent, its whole memory and the arm's angles after every tick.  Run it on two versions of the code (e.g.
``PYTHONPATH=<other checkout>/src``): equal digests mean the change left every output alone.  It uses
only CougarSim's public surface, so it runs on older versions too.
"""

from __future__ import annotations

import argparse
import array
import cProfile
import dataclasses
import hashlib
import math
import pstats
import random
import time
from collections.abc import Callable, Iterator
from typing import Any

from manip.arm import Transform, forward, jacobian
from manip.codecs.cougar import encode
from manip.cougar import Contacts, CougarConfig, CougarSim, GaugeModel, Spring, Surface
from manip.cougar.memory import MAP, MEMORY_BYTES, region

DT = 1 / 60
READY = (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)
TOOL_Z = 864.87 + 150.0  # the tool point's height at READY
TOOL = Transform.trans(0.0, 0.0, 150.0)


def command(name: str, **values: Any) -> list[int]:
    return encode("command", name, **values)


def floats(values: Any) -> tuple[float, ...]:
    return tuple(float(v) for v in values)


def environment() -> Contacts:
    """A ceiling a few mm into the tool's reach at READY, and a weak spring off to one side."""
    ceiling = Surface(point=(0.0, 0.0, TOOL_Z - 3.0), normal=(0.0, 0.0, -1.0), stiffness=4.0)
    spring = Spring(anchor=(200.0, -150.0, 900.0), stiffness=0.05, rest_length=300.0)
    return Contacts((ceiling, spring))


def puma_driver(rng: random.Random) -> Iterator[list[int]]:
    """The words the Puma sends before each tick: moves with SEN, pauses, reads, compliant segments."""
    here = list(READY)
    tick = 0
    while True:
        start, goal = list(here), [q + rng.uniform(-25.0, 25.0) for q in here]
        steps = rng.randint(20, 90)
        compliant = rng.random() < 0.25
        for k in range(1, steps + 1):
            s = 0.5 - 0.5 * math.cos(math.pi * k / steps)
            previous, here = here, [a + (b - a) * s for a, b in zip(start, goal, strict=True)]
            if compliant:
                words = command(
                    "NPR",
                    theta_sensed=floats(here),
                    theta_commanded=floats(q + 0.05 for q in here),
                    rate_difference=floats((a - b) / DT * 0.01 for a, b in zip(here, previous, strict=True)),
                )
            else:
                words = command("SEN", theta_sensed=floats(here))
            if tick % 6 == 0:
                words += command("RFRC")
            if tick % 97 == 0:
                words += command("RRAW")
            tick += 1
            yield words
        for _ in range(rng.randint(0, 60)):  # a pause: nothing moves, the forces are still read
            yield command("RFRC") if tick % 6 == 0 else []
            tick += 1


def setup(sim: CougarSim) -> None:
    """What a Puma sends first: compliance parameters, a frame vector, a guard."""
    sim.receive(command("NK", k=(2.0, 2.0, 2.0, 0.5, 0.5, 0.5)))
    sim.receive(command("NB", b=floats(0.1 if i % 7 == 0 else 0.0 for i in range(36))))
    sim.receive(command("NBJI", bji=(0.02,) * 6))
    sim.receive(command("NFC", force=(0.0, 0.0, 4.0, 0.0, 0.0, 0.0)))
    sim.receive(command("NFV", offset=(0.0, 0.0, 120.0)))
    sim.receive(command("GUARDS", type_index=0x8003, dvec=(0.0, 0.0, 1.0, 0.0, 0.0, 0.0), tol=900.0))


NOISY = GaugeModel(noise=0.7, cross_coupling=0.02, offsets=(5, -3, 0, 2, 7, -1, 4, 0))


def bench_sim(touching: bool = True) -> CougarSim:
    """The bench's Cougar: touching a surface and a spring with noisy gauges, or in free space with
    exact ones (the reference server's default); no re-entries, so every tick works."""
    no_reentry = CougarConfig(guts_base_s=0.0, guts_per_command_s=0.0, guts_per_word_s=0.0)
    if not touching:
        return CougarSim(no_reentry, seed=5)
    return CougarSim(dataclasses.replace(no_reentry, gauges=NOISY), environment=environment(), seed=5)


def script(driver: Iterator[list[int]], ticks: int) -> list[list[int]]:
    """The Puma's words for the next ``ticks`` ticks, made before any timing: only Cougar's work counts."""
    return [next(driver) for _ in range(ticks)]


def run_ticks(
    sim: CougarSim, words: list[list[int]], t0: float = 0.0, clock: Callable[[], float] = time.process_time
) -> float:
    """Hand Cougar each tick's words and tick it; the seconds that took (CPU seconds by default)."""
    t = t0
    start = clock()
    for w in words:
        sim.receive(w)
        sim.tick(t)
        t += DT
    return clock() - start


def warmed_up(seed: int, touching: bool = True) -> tuple[CougarSim, Iterator[list[int]]]:
    sim = bench_sim(touching)
    setup(sim)
    driver = puma_driver(random.Random(seed))
    run_ticks(sim, script(driver, 30))
    return sim, driver


def ticks_per_second(ticks: int, rounds: int, touching: bool = True) -> list[float]:
    rates = []
    for r in range(rounds):
        sim, driver = warmed_up(r, touching)
        rates.append(ticks / run_ticks(sim, script(driver, ticks), 1.0))
    return rates


#: GUTS's parts and JACOB, as CougarSim names them (private names: this is a bench, not a client).
PARTS = {
    "_adc8": "ADC8 (physical load, gauges, filter)",
    "_convert": "conversion (voltmat · Y)",
    "_gravity": "GRAVITY (and LIMIT)",
    "_guardm": "GUARDM",
    "_comint_run": "COMINT (the commands)",
}


def part_costs(ticks: int) -> None:
    """Each part's own time per tick, measured around the part (no profiler; wall-clock time, which a
    busy machine inflates)."""
    sim, driver = warmed_up(0)
    spent: dict[str, float] = dict.fromkeys([*PARTS, "JACOB"], 0.0)

    def timed(name: str, part: Callable[..., Any]) -> Callable[..., Any]:
        def run(*args: Any) -> Any:
            start = time.perf_counter()
            try:
                return part(*args)
            finally:
                spent[name] += time.perf_counter() - start

        return run

    for name in PARTS:
        setattr(sim, name, timed(name, getattr(sim, name)))
    jacob = sim._jacob
    jacob.run = timed("JACOB", jacob.run)  # type: ignore[method-assign]
    whole = run_ticks(sim, script(driver, ticks), 1.0, time.perf_counter)
    print(f"\nper part, µs per tick over {ticks} ticks ({1e6 * whole / ticks:.0f} µs per tick in all):")
    for name, label in [*PARTS.items(), ("JACOB", "JACOB (background, 4 steps)")]:
        print(f"{1e6 * spent[name] / ticks:8.1f}  {label}")
    print(f"{1e6 * (whole - sum(spent.values())) / ticks:8.1f}  the rest (receive, tick, re-entry check)")


def kinematics_costs(calls: int = 3000) -> None:
    """µs per call of the kinematics the tick uses, for fresh angles and for angles asked again."""
    rng = random.Random(1)
    fresh = [tuple(rng.uniform(-170.0, 170.0) for _ in range(6)) for _ in range(calls)]
    again = fresh[0]
    print("\nkinematics, µs per call (CPU time):")
    for label, call in (
        ("forward, fresh angles", forward),
        ("forward, the same angles again", lambda q: forward(again)),
        ("jacobian (tool frame), fresh angles", lambda q: jacobian(q, frame="tool")),
        ("jacobian (tool frame), the same angles again", lambda q: jacobian(again, frame="tool")),
        ("Transform @ Transform", lambda q: TOOL @ TOOL),
    ):
        best = math.inf
        for _ in range(3):
            start = time.process_time()
            for q in fresh:
                call(q)
            best = min(best, time.process_time() - start)
        print(f"{1e6 * best / calls:8.2f}  {label}")


def profile(ticks: int, rows: int = 30) -> None:
    sim, driver = warmed_up(0)
    words = script(driver, ticks)
    profiler = cProfile.Profile()
    profiler.enable()
    run_ticks(sim, words, 1.0)
    profiler.disable()
    stats: dict[tuple[str, int, str], tuple[int, int, float, float, object]] = pstats.Stats(profiler).stats  # type: ignore[attr-defined]
    scale = 1e6 / ticks
    table = []
    for (path, line, name), (_, calls, own, cumulative, _) in stats.items():
        if "/manip/" in path or "/numpy/" in path:
            where = path.split("/src/")[-1].split("site-packages/")[-1]
            table.append((cumulative * scale, own * scale, calls / ticks, f"{where}:{line} {name}"))
    print(f"\nper-part cost, µs per tick over {ticks} ticks (cProfile: inflated, compare rows, not runs):")
    print(f"{'cumulative':>10} {'own':>8} {'calls/tick':>10}  function")
    for total, itself, per_tick, label in sorted(table, reverse=True)[:rows]:
        print(f"{total:10.1f} {itself:8.1f} {per_tick:10.2f}  {label}")


# ----------------------------------------------------------------------------------- digests
def _random_float(rng: random.Random) -> float:
    kind = rng.random()
    if kind < 0.6:
        return rng.uniform(-100.0, 100.0)
    if kind < 0.7:
        return 0.0
    if kind < 0.8:  # saturating, huge, tiny and flushed-to-zero values
        return rng.choice((1e30, -1e30, 1e-30, 1.7e38, -1.7e38, 3e-39))
    return float(rng.randint(-5, 5))


def _random_floats(rng: random.Random, n: int) -> tuple[float, ...]:
    return tuple(_random_float(rng) for _ in range(n))


def _random_address(rng: random.Random) -> int:
    """Mostly a word of a variable; sometimes anywhere, odd or outside memory."""
    if rng.random() < 0.1:
        return rng.randrange(0x10000)
    r = rng.choice([r for r in MAP if r.name != "guts_busy"])
    return r.address + 2 * rng.randrange(r.words)


_RANDOM: dict[str, Callable[[random.Random], dict[str, Any]]] = {
    "NOP": lambda rng: {},
    "RST": lambda rng: {},
    "RFRC": lambda rng: {},
    "RRAW": lambda rng: {},
    "NFC": lambda rng: {"force": _random_floats(rng, 6)},
    "NK": lambda rng: {"k": _random_floats(rng, 6)},
    "NBJI": lambda rng: {"bji": _random_floats(rng, 6)},
    "NB": lambda rng: {"b": _random_floats(rng, 36)},
    "NFV": lambda rng: {"offset": tuple(rng.uniform(-200.0, 200.0) for _ in range(3))},
    "NEWWC": lambda rng: {"weight": abs(_random_float(rng)) % 200.0, "cg": _random_floats(rng, 3)},
    "DPST": lambda rng: {"address": _random_address(rng), "value": rng.randrange(0x10000)},
    "EXMN": lambda rng: {"address": _random_address(rng), "count": rng.randint(0, 120)},
    "VERS": lambda rng: {"version": rng.randrange(0x10000)},
    "GUARDS": lambda rng: {
        "type_index": rng.randrange(0x10000),
        "dvec": tuple(rng.uniform(-1.0, 1.0) for _ in range(6)),
        "tol": rng.uniform(-50.0, 300.0),
    },
    "GUARDC": lambda rng: {"index": rng.randrange(0x10000)},
    "WGOV": lambda rng: {"offsets": tuple(rng.randint(-300, 300) for _ in range(8))},
}


def _with_faults(*faults: str, readings: frozenset[str] = frozenset()) -> CougarSim:
    return CougarSim(
        CougarConfig(faults=frozenset(faults), readings=readings), environment=environment(), seed=7
    )


#: (name, the simulator, seed); seed 0: the Puma driver alone, no random commands or early ticks.
SESSIONS: list[tuple[str, Callable[[], CougarSim], int]] = [
    ("puma-only", bench_sim, 0),
    ("default", CougarSim, 1),
    ("contact+noise", lambda: CougarSim(CougarConfig(gauges=NOISY), environment=environment(), seed=3), 2),
    (
        "limit+payload",
        lambda: CougarSim(
            CougarConfig(limit_on=True, payload_weight_oz=40.0, payload_cg_mm=(10.0, -5.0, 80.0)),
            environment=environment(),
            seed=4,
        ),
        3,
    ),
    (
        "jacob-1-step",
        lambda: CougarSim(
            CougarConfig(jacob_steps_per_tick=1, gauges=NOISY), environment=environment(), seed=5
        ),
        4,
    ),
    ("jacob-3-steps", lambda: CougarSim(CougarConfig(jacob_steps_per_tick=3), seed=6), 5),
    (
        "faults",
        lambda: _with_faults(
            "forces-wrong-sign",
            "npr-ignores-k",
            "filter-con-swapped",
            "guard-trips-twice",
            readings=frozenset({"filter-rounds-to-nearest"}),  # was the fault filter-float-instead-of-integer
        ),
        6,
    ),
    (
        "calibrated",
        lambda: CougarSim(
            CougarConfig(calibration=tuple(((i * 7919) % 97 - 48) / 7.0 for i in range(48)), gauges=NOISY),
            environment=environment(),
            seed=8,
        ),
        7,
    ),
]


def digest(ticks: int) -> str:
    total = hashlib.sha256()
    theta = region("theta_sensed")
    for name, make, seed in SESSIONS:
        h = hashlib.sha256()
        rng = random.Random(seed)
        sim = make()
        setup(sim)
        driver = puma_driver(random.Random(seed))
        t = 0.0
        for _ in range(ticks):
            words = next(driver)
            for _ in range(rng.choice((0, 0, 0, 1, 2)) if seed else 0):
                key = rng.choice(sorted(_RANDOM))
                words += command(key, **_RANDOM[key](rng))
            if seed and rng.random() < 0.02:  # a deposit into θ_sensed: memory and the arm differ
                address = theta.address + 2 * rng.randrange(theta.words)
                words += command("DPST", address=address, value=rng.randrange(0x10000))
            sim.receive(words)
            t += DT * (rng.choice((1.0, 1.0, 1.0, 0.1)) if seed else 1.0)  # too early: a re-entry
            h.update(repr(sim.tick(t)).encode())
            h.update(array.array("H", sim.memory.read_words(0, MEMORY_BYTES // 2)).tobytes())
            h.update(repr(sim.pose).encode())
        h.update(repr((sim.stats, sim.terminal, sim.tool_pose().to_floats())).encode())
        s = sim.stats
        print(
            f"{name:14} {h.hexdigest()[:16]}  ticks {s.ticks}, re-entries {s.guts_reentries}, commands "
            f"{s.commands}, guard trips {s.guards_tripped}, bad addresses {s.bad_addresses}, "
            f"float faults {s.float_faults}"
        )
        total.update(h.digest())
    return total.hexdigest()


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--ticks", type=int, help="ticks per round (3000; --digest: per session, 600)")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--no-profile", action="store_true")
    parser.add_argument("--digest", action="store_true", help="print the output digest instead")
    args = parser.parse_args()
    if args.digest:
        print("all", digest(args.ticks or 600))
        return
    ticks = args.ticks or 3000
    for touching, where in ((True, "touching a surface and a spring"), (False, "in free space")):
        rates = ticks_per_second(ticks, args.rounds, touching)
        best = max(rates)
        print(
            f"CougarSim.tick, {where}: {best:,.0f} ticks/s, best of {args.rounds} ({1e6 / best:.0f} µs "
            f"per tick); all rounds: {', '.join(f'{r:,.0f}' for r in rates)}"
        )
    part_costs(ticks)
    kinematics_costs()
    if not args.no_profile:
        profile(min(ticks, 2000))


if __name__ == "__main__":
    main()
