"""Cougar's simulated core memory and the map of where its variables live (errata ``cougar-memory-map``).

Everything the simulator knows that the Puma could change lives here, as it did in the LSI-11/23: the
compliance parameters, the calibration matrices, the gauge buffers, the guard table, the Jacobian double
buffer, the version word.  Commands write their data words straight to these addresses (COMINT's "location
found from a table", B.7) and every routine reads its inputs back from them, so DPST (deposit) changes
behaviour and EXMN (examine) shows what Cougar is really using.

Addresses are PDP-11 byte addresses (octal in the table) of 16-bit words, so they are even.  A float is an F
float in two consecutive words, sign/exponent word first (the layout on the link, errata ``float-layout``);
a matrix is stored row after row; an int16 is two's complement.  The simulated memory is the low 56 KiB,
0..0o157777; the I/O page above it is not simulated.  An odd address or one outside that range is a bus
error on the real machine: here EXMN retrieves no words and DPST changes nothing (both are counted).

``python -c "from manip.cougar.memory import format_map; print(format_map())"`` prints the map.
"""

from __future__ import annotations

import array
import bisect
import functools
import struct
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Final, Literal, TypeGuard

import numpy as np
import numpy.typing as npt

from manip.codecs.errors import DecodeError
from manip.codecs.pdp11float import F_MAX, pack_f_array, pack_f_few, unpack_f, unpack_f_array, unpack_f_few
from manip.spec.notation import octal

__all__ = [
    "MAP",
    "MEMORY_BYTES",
    "Kind",
    "Memory",
    "Region",
    "format_map",
    "region",
]

#: Bytes of simulated memory: everything below the I/O page.
MEMORY_BYTES: Final = 0o160000
#: Where the map starts; below it the PDP-11 keeps its vectors and stack.
MAP_BASE: Final = 0o1000

Kind = Literal["word", "int16", "float"]
FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Region:
    """One named variable (or array of them) in Cougar memory."""

    name: str
    kind: Kind
    count: int
    description: str
    address: int = 0

    @property
    def words(self) -> int:
        return self.count * (2 if self.kind == "float" else 1)

    @property
    def end(self) -> int:
        """First byte address after the region."""
        return self.address + 2 * self.words

    def at(self, index: int) -> int:
        """Byte address of element ``index``."""
        if not 0 <= index < self.count:
            raise IndexError(f"{self.name} has {self.count} elements, not {index + 1}")
        return self.address + index * (4 if self.kind == "float" else 2)


def _layout(regions: Sequence[Region]) -> tuple[Region, ...]:
    out: list[Region] = []
    address = MAP_BASE
    for r in regions:
        out.append(Region(r.name, r.kind, r.count, r.description, address))
        address += 2 * r.words
    if address > MEMORY_BYTES:
        raise ValueError("the Cougar memory map does not fit in memory")
    return tuple(out)


_J = "6x6, joint rates (deg/s) to compliance-centre velocity (mm/s, deg/s) in hand coordinates"
#: The memory map, in address order.  Names are used by the simulator; addresses follow from the order.
MAP: Final[tuple[Region, ...]] = _layout(
    (
        Region("version", "word", 1, "Cougar's version number, the VERS reply"),
        Region("puma_version", "word", 1, "the version word the Puma last sent with VERS"),
        Region("flags", "word", 1, "bit 0: LIMIT on (off at start, as in the 1985 guide)"),
        Region("guts_busy", "word", 1, "non-zero while GUTS runs: the re-entry check (B.6)"),
        Region("jacob_front", "word", 1, "low bit: which Jacobian buffer (jbuf0/jbuf1) the foreground uses"),
        Region("guard_active", "word", 1, "bit i set: guard i is armed"),
        Region("args", "word", 2, "data words of DPST, EXMN and GUARDC"),
        Region("limit_dead", "float", 1, "LIMIT dead band 'dead' (oz, oz-in); 0.5"),
        Region("limit_clamp", "float", 1, "LIMIT clamp 'tol' (oz, oz-in); 500"),
        Region("con", "float", 4, "output FILTER con1..con4 (B.10)"),
        Region("hand_weight", "float", 1, "hand weight (oz), for GRAVITY"),
        Region("hand_cg", "float", 3, "hand centre of gravity (mm from the wrist centre, hand coordinates)"),
        Region("object", "float", 4, "NEWWC data: object weight (oz), then cg (mm from the frame vector)"),
        Region("grav_weight", "float", 1, "GRAVITY model: hand + object weight (oz)"),
        Region("grav_cg", "float", 3, "GRAVITY model: combined cg (mm from the compliance centre)"),
        Region("fv", "float", 3, "NFV data: frame vector, compliance centre (mm from the wrist centre)"),
        Region("k", "float", 6, "NK data: spring constants (diagonal)"),
        Region("b", "float", 36, "NB data: damping matrix, row after row"),
        Region("bji", "float", 6, "NBJI data: joint damping matrix inverse (diagonal)"),
        Region("fc", "float", 6, "NFC data: force commanded (oz, oz-in)"),
        Region("theta_sensed", "float", 6, "SEN/FINIT/NPR data: joint angles (deg)"),
        Region("theta_commanded", "float", 6, "NPR data: commanded joint angles (deg)"),
        Region("rate_difference", "float", 6, "NPR data: sensed minus commanded joint rate (deg/s)"),
        Region("dtheta_previous", "float", 6, "FILTER: previous compliance sample"),
        Region("dtheta_filtered", "float", 6, "FILTER: filtered value"),
        Region("dtheta_out", "float", 6, "RATEO: the last NTD sent"),
        Region("gauge_offsets", "int16", 8, "WGOV data: gauge offset vector"),
        Region("gauge_raw", "int16", 8, "ADC8: latest samples less the offsets u_k (u_k-1 next tick)"),
        Region("gauge_filtered", "int16", 8, "ADC8: filtered readings Y_k, offsets already subtracted"),
        Region("force_sensed", "float", 6, "voltmat times (Y - offsets): before GRAVITY"),
        Region("force", "float", 6, "gravity-corrected (and LIMITed) force: RFRC, guards, NPR"),
        Region("calmat", "float", 48, "the wrist's calibration matrix (oz/V, oz-in/V), 6x8"),
        Region("voltmat", "float", 48, "calmat x 10/2048 x -1, compliance-centre transform applied"),
        Region("guard_in", "word", 15, "GUARDS data as received"),
        Region("guards", "word", 16 * 15, "16 guards: type/index word, dvec (6 floats), tol (float)"),
        Region("jbuf0", "float", 108, f"Jacobian buffer 0: J ({_J}), J transpose, P = BJI J^T"),
        Region("jbuf1", "float", 108, "Jacobian buffer 1, the same layout"),
    )
)
_BY_NAME: Final = {r.name: r for r in MAP}
_WORD_INDEX: Final = {r.name: r.address // 2 for r in MAP}
#: Offsets (in floats) inside a Jacobian buffer.
JBUF_J, JBUF_JT, JBUF_P = 0, 36, 72
#: Up to this many floats, the scalar codecs beat numpy's fixed cost per call.
_SMALL: Final = 12
#: Up to this many floats (J, Jᵀ and P: 108), the few-float codecs (``pack_f_few``, ``unpack_f_few``)
#: beat numpy's.
_FEW: Final = 128
#: Words per guard table entry, and where its parts start (in words).
GUARD_WORDS, GUARD_DVEC, GUARD_TOL = 15, 1, 13


def region(name: str) -> Region:
    """The region called ``name``; KeyError if there is none."""
    return _BY_NAME[name]


def format_map() -> str:
    """The map as a table: octal address, words, kind, name, what it holds."""
    lines = ["address  words  kind   name              contents"]
    for r in MAP:
        count = f"{r.kind}[{r.count}]" if r.count > 1 else r.kind
        lines.append(f"{r.address:06o}  {r.words:5d}  {count:<12} {r.name:<17} {r.description}")
    return "\n".join(lines)


class Memory:
    """56 KiB of 16-bit words addressed by even byte address, as the LSI-11/23 saw them.

    Word access outside the memory or at an odd address raises ``ValueError`` here; the protocol layer
    (EXMN/DPST) checks with :meth:`valid` first and reports instead.  Float writes round to the F format
    (half-even) and saturate at the largest F magnitude; float reads take the FP11's undefined variable
    (-0) as 0.0.  ``float_faults`` counts the stores that had to saturate.

    The words are the truth.  A float region's decoded values are kept (:meth:`floats`, :meth:`array`)
    until any store touches one of its words, whichever method stores it, so a routine that reads a
    variable every tick decodes it only after it changed.
    """

    def __init__(self) -> None:
        self._bytes = bytearray(MEMORY_BYTES)
        self._words = memoryview(self._bytes).cast("H")
        self.float_faults = 0
        self._floats: dict[str, tuple[float, ...]] = {}
        self._arrays: dict[str, FloatArray] = {}

    def __len__(self) -> int:
        return MEMORY_BYTES

    @staticmethod
    def valid(address: int, words: int = 1) -> bool:
        """Whether ``words`` words starting at byte ``address`` are all simulated memory."""
        return address % 2 == 0 and address >= 0 and address + 2 * words <= MEMORY_BYTES

    def _check(self, address: int, words: int) -> int:
        if not self.valid(address, words):
            raise ValueError(f"no {words} word(s) of Cougar memory at {octal(address)}")
        return address // 2

    def _stored(self, index: int, words: int) -> None:
        """Words ``index``.. (word indexes) were stored: forget the decoded regions they overlap."""
        if not self._floats or index >= _MAP_WORDS:  # (every region in _arrays is in _floats too)
            return
        end = min(index + words, _MAP_WORDS)
        for name in _FLOAT_NAMES[_FIRST_ENDING_AFTER[index] : _FIRST_STARTING_AT[end]]:
            self._floats.pop(name, None)
            self._arrays.pop(name, None)

    # ------------------------------------------------------------------ words
    def read_word(self, address: int) -> int:
        return int(self._words[self._check(address, 1)])

    def write_word(self, address: int, value: int) -> None:
        if not 0 <= value <= 0xFFFF:
            raise ValueError(f"{value!r} is not a 16-bit word")
        i = self._check(address, 1)
        self._words[i] = value
        self._stored(i, 1)

    def read_words(self, address: int, count: int) -> list[int]:
        i = self._check(address, count)
        return list(self._words[i : i + count])

    def write_words(self, address: int, values: Sequence[int]) -> None:
        i = self._check(address, len(values))
        try:
            self._words[i : i + len(values)] = array.array("H", values)
        except (OverflowError, TypeError):
            pass  # not all 16-bit words: stored one by one below, up to the bad one
        else:
            self._stored(i, len(values))
            return
        try:
            for j, v in enumerate(values):
                if not 0 <= v <= 0xFFFF:
                    raise ValueError(f"{v!r} is not a 16-bit word")
                self._words[i + j] = v
        finally:  # the words before a bad one are stored, as they were
            self._stored(i, len(values))

    # ------------------------------------------------------------------ int16
    def read_int16s(self, address: int, count: int) -> npt.NDArray[np.int64]:
        return np.array(self.int16_list(address, count), dtype=np.int64)

    def int16_list(self, address: int, count: int) -> list[int]:
        """``count`` int16s from ``address``, as Python ints."""
        i = self._check(address, count)
        return list(_int16s(count).unpack_from(self._bytes, 2 * i))

    def write_int16s(self, address: int, values: Iterable[int]) -> None:
        data = [int(v) for v in values]
        if data and not (min(data) >= -0x8000 and max(data) <= 0x7FFF):
            raise ValueError(f"{data} are not all 16-bit signed integers")
        i = self._check(address, len(data))
        _int16s(len(data)).pack_into(self._bytes, 2 * i, *data)
        self._stored(i, len(data))

    # ------------------------------------------------------------------ floats
    def read_floats(self, address: int, count: int) -> FloatArray:
        return np.array(self._decode(address, count), dtype=np.float64)

    def _decode(self, address: int, count: int) -> list[float]:
        i = self._check(address, 2 * count)
        raw = bytes(self._bytes[2 * i : 2 * i + 4 * count])
        if count <= _SMALL:
            try:
                return [unpack_f(raw, offset) for offset in range(0, 4 * count, 4)]
            except DecodeError:
                pass  # the reserved operand: the array decoder reads it as 0.0
        elif count <= _FEW:
            values = unpack_f_few(raw)
            if values is not None:
                return values
        return unpack_f_array(raw, reserved="zero").tolist()  # type: ignore[no-any-return]

    def write_floats(self, address: int, values: Iterable[float] | FloatArray) -> None:
        self.store_encoded(address, *self.encode_floats(values))

    @staticmethod
    def encode_floats(values: Iterable[float] | FloatArray) -> tuple[bytes, bool]:
        """The F words :meth:`write_floats` stores for ``values`` (wire byte order), and whether the store
        saturates (a value not finite or beyond the F range): for a routine that stores the same values
        again and again (:meth:`store_encoded`)."""
        few: Sequence[float] | None = None
        if isinstance(values, np.ndarray):
            if values.dtype == np.float64 and 0 < values.size <= _FEW:
                few = values.reshape(-1).tolist()
        elif isinstance(values, (list, tuple)) and 0 < len(values) <= _FEW:
            few = values
        if few is not None:
            raw = pack_f_few(few)
            if raw is not None:
                return raw, False
        x = np.array(values, dtype=np.float64).reshape(-1)
        # one reduction: NaN and infinities fail the comparison too
        if not x.size or np.abs(x).max() <= F_MAX:
            return pack_f_array(x), False
        safe = np.clip(np.nan_to_num(x, nan=0.0, posinf=F_MAX, neginf=-F_MAX), -F_MAX, F_MAX)
        return pack_f_array(safe), True

    def store_encoded(self, address: int, raw: bytes, saturated: bool = False) -> None:
        """Store floats encoded by :meth:`encode_floats` (counting the saturation as a float fault)."""
        if saturated:
            self.float_faults += 1
        words = len(raw) // 2
        i = self._check(address, words)
        self._bytes[2 * i : 2 * i + len(raw)] = raw
        self._stored(i, words)

    # ------------------------------------------------------------------ named regions
    def floats(self, name: str) -> tuple[float, ...]:
        """A float region's values as Python floats (decoded once per change)."""
        try:
            return self._floats[name]
        except KeyError:
            pass
        r = _BY_NAME[name]
        if r.kind != "float":
            raise TypeError(f"{name} is not a float region")
        values = tuple(self._decode(r.address, r.count))
        self._floats[name] = values
        return values

    def array(self, name: str) -> FloatArray:
        """A float region's values as a read-only array (decoded once per change)."""
        try:
            return self._arrays[name]
        except KeyError:
            pass
        values = np.array(self.floats(name), dtype=np.float64)
        values.flags.writeable = False
        self._arrays[name] = values
        return values

    def get(self, name: str) -> FloatArray:
        """A float region's values (a new array)."""
        return np.array(self.floats(name), dtype=np.float64)

    def put(self, name: str, values: Iterable[float] | FloatArray) -> None:
        """Store a float region's values (the whole region)."""
        r = _BY_NAME[name]
        if _plain_floats(values, r.count) and r.kind == "float":
            self.write_floats(r.address, values)
            return
        x = np.array(values, dtype=np.float64).reshape(-1)
        if r.kind != "float" or x.size != r.count:
            raise ValueError(f"{name} holds {r.count} {r.kind} values, not {x.size} floats")
        self.write_floats(r.address, x)

    def get_int16s(self, name: str) -> npt.NDArray[np.int64]:
        r = _BY_NAME[name]
        return self.read_int16s(r.address, r.count)

    def int16s(self, name: str) -> list[int]:
        """An int16 region's values as Python ints."""
        r = _BY_NAME[name]
        return self.int16_list(r.address, r.count)

    def put_int16s(self, name: str, values: Iterable[int]) -> None:
        r = _BY_NAME[name]
        data = list(values)
        if r.kind != "int16" or len(data) != r.count:
            raise ValueError(f"{name} holds {r.count} {r.kind} values, not {len(data)} int16s")
        self.write_int16s(r.address, data)

    def word(self, name: str, index: int = 0) -> int:
        if index:
            return self.read_word(_BY_NAME[name].at(index))
        return int(self._words[_WORD_INDEX[name]])

    def set_word(self, name: str, value: int, index: int = 0) -> None:
        if index or not 0 <= value <= 0xFFFF:
            self.write_word(_BY_NAME[name].at(index), value)
            return
        i = _WORD_INDEX[name]
        self._words[i] = value
        self._stored(i, 1)


# Float regions by word index, for forgetting decoded values.  A store to words [start, end) touches the
# float regions _FLOAT_NAMES[_FIRST_ENDING_AFTER[start]:_FIRST_STARTING_AT[end]] (none when the slice is
# empty); both tables are the bisections worked out once for every word of the map.
_FLOAT_NAMES: Final = [r.name for r in MAP if r.kind == "float"]
_FLOAT_STARTS: Final = [r.address // 2 for r in MAP if r.kind == "float"]
_FLOAT_ENDS: Final = [r.end // 2 for r in MAP if r.kind == "float"]
_MAP_WORDS: Final = MAP[-1].end // 2
_FIRST_ENDING_AFTER: Final = [bisect.bisect_right(_FLOAT_ENDS, i) for i in range(_MAP_WORDS)]
_FIRST_STARTING_AT: Final = [bisect.bisect_left(_FLOAT_STARTS, i) for i in range(_MAP_WORDS + 1)]


def _plain_floats(values: object, count: int) -> TypeGuard[Sequence[float]]:
    """Whether ``values`` is a list or tuple of ``count`` Python floats (no array needed)."""
    if not isinstance(values, (list, tuple)) or len(values) != count:
        return False
    return all(type(v) is float for v in values)


@functools.cache
def _int16s(count: int) -> struct.Struct:
    return struct.Struct(f"<{count}h")
