"""Wire-level building blocks shared by the element and site protocols.

Everything on the wire is little-endian: IDs are int32 arrays, vectors are float64
arrays, with no header (spec §2.1). Signal blocks always travel in OpenFresco's order
disp, vel, accel, force, time (``OF_Resp_Disp..OF_Resp_Time``), each block present only
when its size is non-zero (spec §3.4). The :class:`BlockLayout` precompiles the
``struct.Struct`` objects for one such layout so the per-message work is a single
``unpack_from``/``pack_into`` call.
"""

from __future__ import annotations

import enum
import functools
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar, Final, NamedTuple, TypeAlias

from protocol.errors import LocalProtocolError, RemoteProtocolError

__all__ = [
    "ACTION_BY_CODE",
    "DOUBLE_BYTES",
    "INT_BYTES",
    "SIGNAL_NAMES",
    "Action",
    "BlockLayout",
    "ReadableBuffer",
    "SignalSizes",
    "Signals",
    "SizeID",
    "doubles_struct",
    "pack_blocks",
    "unpack_blocks",
]

ReadableBuffer: TypeAlias = bytes | bytearray | memoryview
"""What ``receive_data`` and the decoders accept."""

DOUBLE_BYTES: Final = 8
INT_BYTES: Final = 4
SIGNAL_NAMES: Final = ("disp", "vel", "accel", "force", "time")
"""Block order on the wire (``OF_Resp_Disp`` .. ``OF_Resp_Time``)."""

_SIZE_ID_STRUCT: Final = struct.Struct("<11i")
_SIZE_ID_ENTRY_NAMES: Final = (
    "sizeCtrl disp",
    "sizeCtrl vel",
    "sizeCtrl accel",
    "sizeCtrl force",
    "sizeCtrl time",
    "sizeDaq disp",
    "sizeDaq vel",
    "sizeDaq accel",
    "sizeDaq force",
    "sizeDaq time",
    "dataSize",
)


@functools.lru_cache(maxsize=256)
def doubles_struct(count: int) -> struct.Struct:
    """Return the cached little-endian ``Struct`` for *count* float64 values."""
    return struct.Struct(f"<{count}d")


class Action(enum.IntEnum):
    """Action codes carried in slot 0 of a request vector (``OF_RemoteTest_*``, spec §3.5)."""

    OPEN = 1
    SETUP = 2
    SET_TRIAL_RESPONSE = 3
    EXECUTE = 4
    COMMIT_STATE = 5
    GET_DAQ_RESPONSE = 6
    GET_DISP = 7
    GET_VEL = 8
    GET_ACCEL = 9
    GET_FORCE = 10
    GET_TIME = 11
    GET_INITIAL_STIFF = 12
    GET_TANGENT_STIFF = 13
    GET_DAMP = 14
    GET_MASS = 15
    SHUTDOWN = 98
    DIE = 99


ACTION_BY_CODE: Final[dict[float, Action]] = {float(a.value): a for a in Action}
"""Float slot-0 value -> Action; a dict hit is the fast path of every decoded vector."""


@dataclass(frozen=True, slots=True)
class SignalSizes:
    """Number of values per signal block, in wire order d, v, a, f, t."""

    disp: int = 0
    vel: int = 0
    accel: int = 0
    force: int = 0
    time: int = 0

    def __post_init__(self) -> None:
        for name, value in zip(SIGNAL_NAMES, self.as_tuple(), strict=True):
            if value < 0:
                raise ValueError(f"signal size {name} = {value} is negative")

    @property
    def total(self) -> int:
        """Slots needed for all blocks together."""
        return self.disp + self.vel + self.accel + self.force + self.time

    def as_tuple(self) -> tuple[int, int, int, int, int]:
        """The five sizes in wire order."""
        return (self.disp, self.vel, self.accel, self.force, self.time)

    def encode(self) -> bytes:
        """The 5 x int32 ID the site protocol sends for sizeTrial / sizeOut (spec §4.3)."""
        return _SIGNAL_SIZES_STRUCT.pack(*self.as_tuple())



_SIGNAL_SIZES_STRUCT: Final = struct.Struct("<5i")


class Signals(NamedTuple):
    """One set of signal blocks in wire order: trial/ctrl or out/daq values.

    Immutable, compared by value and matchable by field, as a frozen dataclass would be, but
    a named tuple: one is made for every trial and every measured reply (6 a step for
    OpenSees), and a named tuple costs less than half as much to make.
    """

    disp: tuple[float, ...] = ()
    vel: tuple[float, ...] = ()
    accel: tuple[float, ...] = ()
    force: tuple[float, ...] = ()
    time: tuple[float, ...] = ()

    def as_tuple(self) -> tuple[tuple[float, ...], ...]:
        """The five blocks in wire order."""
        return (self.disp, self.vel, self.accel, self.force, self.time)

    def sizes(self) -> SignalSizes:
        """The block lengths as a :class:`SignalSizes`."""
        return SignalSizes(
            len(self.disp), len(self.vel), len(self.accel), len(self.force), len(self.time)
        )


def _size_id_problem(values: Sequence[int], max_data_size: int | None) -> tuple[str, bool]:
    """Return (problem text or "", time_slot_missing) for the 11 size-ID entries."""
    for index, value in enumerate(values):
        if value < 0:
            name = _SIZE_ID_ENTRY_NAMES[index]
            return f"size ID entry {index} ({name}) = {value} is negative", False
    data_size = values[10]
    if data_size < 1:
        return (
            f"size ID entry 10 (dataSize) = {data_size} must be at least 1 "
            "(every vector has the action code in slot 0)",
            False,
        )
    if max_data_size is not None and data_size > max_data_size:
        return (
            f"size ID entry 10 (dataSize) = {data_size} exceeds the configured cap {max_data_size}",
            False,
        )
    daq_total = sum(values[5:10])
    if daq_total > data_size:
        return (
            f"size ID daq sizes (entries 5-9) sum to {daq_total} but dataSize (entry 10) is "
            f"{data_size}: a reply cannot hold the daq blocks",
            False,
        )
    ctrl_total = sum(values[0:5])
    if 1 + ctrl_total <= data_size:
        return "", False
    if 1 + ctrl_total - values[4] <= data_size:
        # MATLAB GenericClient2d declares a time slot that does not fit (spec §6.1):
        # accept it and read the time as 0.
        return "", True
    return (
        f"size ID ctrl sizes (entries 0-4) need 1 + {ctrl_total} slots but dataSize "
        f"(entry 10) is {data_size}: the trial blocks do not fit",
        False,
    )


class _SizeIDBytes:
    """``SizeID.SIZE_BYTES``: a ClassVar in a base class, not in the frozen dataclass itself,
    which mypyc compiles as a slot that ``__init__`` then fails to set (setup.py)."""

    __slots__ = ()
    SIZE_BYTES: ClassVar[int] = 44


@dataclass(frozen=True, slots=True)
class SizeID(_SizeIDBytes):
    """The 11 x int32 size ID that opens an element-protocol connection (spec §3.3)."""

    ctrl: SignalSizes
    daq: SignalSizes
    data_size: int

    def __post_init__(self) -> None:
        problem, _ = _size_id_problem(self._entries(), None)
        if problem:
            raise ValueError(problem)

    def _entries(self) -> tuple[int, ...]:
        return (*self.ctrl.as_tuple(), *self.daq.as_tuple(), self.data_size)

    @property
    def vector_bytes(self) -> int:
        """Bytes of every vector after the ID, in both directions."""
        return DOUBLE_BYTES * self.data_size

    @property
    def ctrl_time_fits(self) -> bool:
        """False when the ctrl time slot lies past dataSize (then it is read as 0)."""
        return 1 + self.ctrl.total <= self.data_size

    def encode(self) -> bytes:
        """The 44 bytes sent as the first item of the connection."""
        return _SIZE_ID_STRUCT.pack(*self._entries())

    @classmethod
    def decode(cls, data: ReadableBuffer, *, max_data_size: int = 65536, offset: int = 0) -> SizeID:
        """Decode and validate 44 bytes at *offset*; RemoteProtocolError when invalid."""
        available = memoryview(data).nbytes - offset
        if available < cls.SIZE_BYTES:
            raise RemoteProtocolError(
                f"size ID needs {cls.SIZE_BYTES} bytes, only {available} available"
            )
        values = _SIZE_ID_STRUCT.unpack_from(data, offset)
        problem, _ = _size_id_problem(values, max_data_size)
        if problem:
            raise RemoteProtocolError(problem)
        return cls(SignalSizes(*values[0:5]), SignalSizes(*values[5:10]), values[10])

    @classmethod
    def for_generic_client(cls, n: int, data_size: int = 256) -> SizeID:
        """The ID OpenSees ``genericClient`` sends for *n* basic DOFs and ``-dataSize``.

        dataSize is raised to ``1 + 3n + 1`` and then to ``n*n`` when smaller.
        """
        if n < 1:
            raise ValueError(f"genericClient needs at least 1 basic DOF, got n = {n}")
        size = max(data_size, 1 + 3 * n + 1, n * n)
        return cls(SignalSizes(n, n, n, 0, 1), SignalSizes(0, 0, 0, n, 0), size)


class BlockLayout:
    """Precompiled positions of the d,v,a,f,t blocks of *sizes* inside one vector.

    Blocks are packed back to back from *start_slot* (1 for trial/ctrl, 0 for out/daq).
    With ``allow_missing_time`` a time block that does not fit is decoded as zeros.
    """

    __slots__ = (
        "_all_struct",
        "_block_structs",
        "_bounds",
        "_time_zeros",
        "counts",
        "data_size",
        "offsets",
        "sizes",
        "start_slot",
        "time_missing",
    )

    def __init__(
        self,
        sizes: SignalSizes,
        start_slot: int,
        data_size: int,
        *,
        allow_missing_time: bool = False,
        role: str = "signal",
    ) -> None:
        self.sizes = sizes
        self.start_slot = start_slot
        self.data_size = data_size
        self.counts = counts = sizes.as_tuple()
        """The five block sizes in wire order (compared at once with a vector's lengths)."""
        used = start_slot + sizes.total
        self.time_missing = False
        if used > data_size:
            if allow_missing_time and used - sizes.time <= data_size:
                self.time_missing = True
            else:
                raise ValueError(
                    f"{role} blocks need slots {start_slot}..{used - 1} but the vector has "
                    f"only {data_size} slots"
                )
        bounds: list[tuple[int, int]] = []
        offsets: list[int] = []
        slot = start_slot
        for count in counts:
            bounds.append((slot - start_slot, slot - start_slot + count))
            offsets.append(DOUBLE_BYTES * slot)
            slot += count
        self._bounds: tuple[tuple[int, int], ...] = tuple(bounds)
        self.offsets: tuple[int, ...] = tuple(offsets)
        decoded = sizes.total - (sizes.time if self.time_missing else 0)
        self._all_struct = doubles_struct(decoded)
        self._block_structs = tuple(doubles_struct(c) for c in counts)
        self._time_zeros: tuple[float, ...] = (0.0,) * sizes.time

    def unpack_from(self, buffer: ReadableBuffer, offset: int = 0) -> Signals:
        """Decode all blocks of the vector that starts at byte *offset* of *buffer*."""
        values = self._all_struct.unpack_from(buffer, offset + DOUBLE_BYTES * self.start_slot)
        (d0, d1), (v0, v1), (a0, a1), (f0, f1), (t0, t1) = self._bounds
        time = self._time_zeros if self.time_missing else values[t0:t1]
        return Signals(values[d0:d1], values[v0:v1], values[a0:a1], values[f0:f1], time)

    def check(self, signals: Signals, role: str) -> None:
        """LocalProtocolError unless every block length equals its declared size."""
        for name, block, size in zip(
            SIGNAL_NAMES, signals.as_tuple(), self.sizes.as_tuple(), strict=True
        ):
            if len(block) != size:
                raise LocalProtocolError(
                    f"{role} {name} block has {len(block)} values but the negotiated size is {size}"
                )

    def pack_into(self, buffer: bytearray, signals: Signals, role: str = "signal") -> None:
        """Write all blocks (lengths checked) into *buffer* at their packed offsets."""
        if self.time_missing:
            raise LocalProtocolError(
                f"{role} time block lies past dataSize {self.data_size}: cannot be sent"
            )
        if tuple(map(len, signals)) != self.counts:
            self.check(signals, role)  # raises, naming the block
        self.pack_exact_into(buffer, signals)

    def pack_exact_into(self, buffer: bytearray, signals: Signals) -> None:
        """``pack_into`` for blocks already known to have exactly their sizes (unchecked)."""
        self._all_struct.pack_into(
            buffer,
            DOUBLE_BYTES * self.start_slot,
            *signals.disp,
            *signals.vel,
            *signals.accel,
            *signals.force,
            *signals.time,
        )

    def pack_block_into(
        self, buffer: bytearray, index: int, values: Sequence[float], role: str = "signal"
    ) -> None:
        """Write block *index* (0=disp .. 4=time) at its packed offset, length checked."""
        size = self.sizes.as_tuple()[index]
        if len(values) != size:
            raise LocalProtocolError(
                f"{role} {SIGNAL_NAMES[index]} block has {len(values)} values but the "
                f"negotiated size is {size}"
            )
        if size:
            if index == 4 and self.time_missing:
                raise LocalProtocolError(
                    f"{role} time block lies past dataSize {self.data_size}: cannot be sent"
                )
            self._block_structs[index].pack_into(buffer, self.offsets[index], *values)


def pack_blocks(sizes: SignalSizes, signals: Signals, data_size: int, start_slot: int) -> bytearray:
    """A fresh vector of *data_size* doubles with *signals* packed from *start_slot*."""
    buffer = bytearray(DOUBLE_BYTES * data_size)
    BlockLayout(sizes, start_slot, data_size).pack_into(buffer, signals)
    return buffer


def unpack_blocks(
    sizes: SignalSizes, data: ReadableBuffer, start_slot: int, *, offset: int = 0
) -> Signals:
    """Decode the blocks of *sizes* packed from *start_slot* of the vector in *data*."""
    data_size = (memoryview(data).nbytes - offset) // DOUBLE_BYTES
    return BlockLayout(sizes, start_slot, data_size).unpack_from(data, offset)
