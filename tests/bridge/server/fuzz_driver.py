"""A live bridge under hostile input, and the invariants that must hold after every input.

Shared by the hypothesis state machine (``test_fuzz_stateful.py``, CI) and the long run
(``benchmarks/bench_fuzz.py``, >= 100 000 inputs). Every action takes its randomness as
arguments, so hypothesis (shrinking) and a seeded generator drive the same code.

Sites: ``good`` (only ever used by the well-behaved client of the invariant check), ``fuzz``
(TCP) and ``fuzzu`` (UDP), all an elastic specimen of stiffness ``K`` behind absolute limits
±``LIMIT`` mm and an increment limit, policy ``reject``. A spy on every controller's
``set_ctrl_now`` records what reached a controller.
"""

from __future__ import annotations

import contextlib
import math
import os
import socket
import struct
import textwrap
import time
from collections import deque
from pathlib import Path

from fresco_bridge.controls.base import InlineController
from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record import read_record
from fresco_bridge.record.export import pair_commits
from protocol import Action, ElementClientSession, ProtocolError, SizeID
from tests.support.bridge import RunningBridge

K = 10.0
LIMIT = 5.0
INCREMENT = 2.0
MAX_HELD = 8
"""Connections the fuzzer keeps open at once (the oldest is dropped past it)."""
RSS_SLACK = 150 << 20
FD_SLACK = 24
FD_SETTLE = 5.0
"""Seconds a loaded machine gets to close sockets before the fd bound is asserted."""

CONFIG = textwrap.dedent("""
    [bridge]
    run_name = "fuzz"
    max_data_size = 64
    session_idle_timeout = 0.5
    controller_recovery = 0.0
    [record]
    fsync = "off"
    [telemetry]
    monitors = false
    """) + "".join(textwrap.dedent(f"""
    [[sites]]
    name = "{name}"
    port = 0
    transport = "{transport}"
    [sites.controller]
    model = "elastic"
    params = {{ k = {K} }}
    [[sites.limits]]
    disp_min = {-LIMIT}
    disp_max = {LIMIT}
    disp_increment = {INCREMENT}
    """) for name, transport in (("good", "tcp"), ("fuzz", "tcp"), ("fuzzu", "udp")))


def _rss() -> int:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _fds() -> int:
    return len(os.listdir("/proc/self/fd"))


class FuzzTarget:
    """One running bridge, the fuzzer's open connections, and the invariant checks."""

    def __init__(self, run_root: Path) -> None:
        self.bridge: BridgeThread = RunningBridge(CONFIG, run_root).__enter__()
        self.sent: list[tuple[float, ...]] = []
        for site in self.bridge.bridge.sites.values():
            controller = site.controller
            assert isinstance(controller, InlineController), "set_ctrl_now is what is spied"
            original = controller.set_ctrl_now

            def spy(ctrl: tuple[float, ...], _orig=original) -> None:  # type: ignore[no-untyped-def]
                self.sent.append(tuple(ctrl))
                _orig(ctrl)

            controller.set_ctrl_now = spy  # type: ignore[method-assign]
        self.held: deque[socket.socket] = deque()
        self.inputs = 0
        self.good_sessions = 0
        self.step = 0
        self.baseline_fds = _fds()
        self.baseline_rss = _rss()
        self.peak_rss = self.baseline_rss
        self.peak_fds = self.baseline_fds
        self.checked_sent = 0

    def close(self) -> None:
        while self.held:
            self.held.popleft().close()
        self.bridge.stop()

    @property
    def run_dir(self) -> Path:
        return self.bridge.run_dir

    # -- actions -------------------------------------------------------------------------------
    def _connect(self, site: str = "fuzz") -> socket.socket | None:
        try:
            s = socket.create_connection(("127.0.0.1", self.bridge.ports[site]), timeout=1.0)
        except OSError:
            return None
        self.inputs += 1
        return s

    def _keep(self, s: socket.socket, keep_open: bool) -> None:
        if not keep_open:
            s.close()
            return
        self.held.append(s)
        while len(self.held) > MAX_HELD:
            self.held.popleft().close()

    def garbage(self, data: bytes, keep_open: bool) -> None:
        """Arbitrary bytes on a new TCP connection."""
        s = self._connect()
        if s is None:
            return
        with contextlib.suppress(OSError):
            s.sendall(data)
            self.inputs += 1
        self._keep(s, keep_open)

    def frames(self, size_id: tuple[int, ...], vectors: list[tuple[float, ...]],
               keep_open: bool) -> None:
        """An arbitrary (possibly absurd) size ID, then vectors of its dataSize (≤ 64)."""
        s = self._connect()
        if s is None:
            return
        n = min(max(size_id[10], 1), 64)
        with contextlib.suppress(OSError):
            s.sendall(struct.pack("<11i", *size_id))
            self.inputs += 1
            for v in vectors:
                s.sendall(struct.pack(f"<{n}d", *(list(v) + [0.0] * n)[:n]))
                self.inputs += 1
        self._keep(s, keep_open)

    def session(self, disps: list[float], requests: list[int], commit: bool,
                vanish: bool) -> None:
        """A well-formed session sending hostile values (NaN, inf, beyond the limits), any
        request codes, maybe vanishing mid-step."""
        link = GenericClientLink("127.0.0.1", self.bridge.ports["fuzz"], 1, data_size=1,
                                 timeout=2.0)
        try:
            link.connect()
            self.inputs += 1
            for d, code in zip(disps, requests, strict=False):
                link.set_trial((d,), time=0.01)
                self.inputs += 1
                if 7 <= code <= 15:
                    link.request(Action(code))
                else:
                    assert link.sock is not None
                    link.sock.sendall(struct.pack("<5d", float(code), 0, 0, 0, 0))
                self.inputs += 1
                if commit:
                    link.commit()
                    self.inputs += 1
        except (OSError, ValueError, ProtocolError):
            pass  # refused (busy, HOLD), closed by the bridge, or an unanswered code
        if vanish and link.sock is not None:
            link.sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            link.sock.close()  # RST, no DIE
            link.sock = None
            return
        with contextlib.suppress(ProtocolError):
            link.close()  # DIE where the session state allows it
        if link.sock is not None:
            link.sock.close()

    def udp(self, datagrams: list[bytes]) -> None:
        """Datagrams from a fresh address (port): handshakes, garbage, partial items."""
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for d in datagrams:
                with contextlib.suppress(OSError):
                    s.sendto(d, ("127.0.0.1", self.bridge.ports["fuzzu"]))
                    self.inputs += 1

    def drop(self, index: int, reset: bool) -> None:
        """A held connection's peer vanishes (RST) or closes (FIN)."""
        if not self.held:
            return
        s = self.held[index % len(self.held)]
        self.held.remove(s)
        if reset:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        s.close()

    def operator(self, command: str, site: str) -> None:
        desk = self.bridge.bridge.desk
        self.bridge.call(lambda: desk.execute(command, site, source="fuzz"))

    # -- invariants ----------------------------------------------------------------------------
    def check(self, *, record: bool = True) -> None:
        """Every invariant: commands safe, a good client served, fds and memory bounded, the
        record readable."""
        for ctrl in self.sent[self.checked_sent:]:
            assert all(math.isfinite(c) and -LIMIT <= c <= LIMIT for c in ctrl), ctrl
        self.checked_sent = len(self.sent)
        self.good_client()
        fd_bound = self.baseline_fds + len(self.held) + FD_SLACK
        deadline = time.monotonic() + FD_SETTLE
        while (fds := _fds()) > fd_bound and time.monotonic() < deadline:
            time.sleep(0.02)  # the bridge closes a vanished peer's socket on its own thread
        rss = _rss()
        self.peak_fds, self.peak_rss = max(self.peak_fds, fds), max(self.peak_rss, rss)
        assert fds <= fd_bound, (fds, self.baseline_fds)
        assert rss <= self.baseline_rss + RSS_SLACK, (rss, self.baseline_rss)
        if record:
            pair_commits(read_record(self.run_dir))  # raises on a malformed line

    def good_client(self) -> None:
        """The ``good`` site serves a well-behaved client correctly (forces = K · disp)."""
        self.step += 1
        d = ((self.step % 7) - 3) * 0.5  # within every limit, moving at most 2 mm
        with GenericClientLink("127.0.0.1", self.bridge.ports["good"], 1, data_size=1,
                               timeout=10.0) as link:
            link.set_trial((d,), time=0.01 * self.step)
            force = link.force()[0]
            assert force == K * d, (force, d)
            link.commit()
        self.good_sessions += 1


def valid_size_id(data_size: int) -> tuple[int, ...]:
    """The 11 ints of a genericClient size ID (1 DOF) with ``data_size``."""
    sid = SizeID.for_generic_client(1, data_size)
    return tuple(struct.unpack("<11i", ElementClientSession(sid).start()))
