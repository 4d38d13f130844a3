"""Hypothesis stateful fuzzing of a live bridge: mixed sessions, malformed and adversarial
frames, interleavings, vanishing peers, operator commands; after every step the invariants of
``FuzzTarget.check`` hold (a good client is served correctly, no non-finite or out-of-limit
command reached a controller, memory and file descriptors bounded, the record parses). The
long run (>= 100 000 inputs) is ``benchmarks/bench_fuzz.py``.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, rule

from tests.bridge.server.fuzz_driver import LIMIT, FuzzTarget, valid_size_id

floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
hostile_disp = st.one_of(
    st.floats(-LIMIT, LIMIT), st.sampled_from([float("nan"), float("inf"), -1e308, 1e3]),
    floats)
ints = st.integers(-(2**31), 2**31 - 1)
small_ints = st.integers(-2, 70)

_target: FuzzTarget | None = None
_root: Path | None = None


def target() -> FuzzTarget:
    """One bridge for the whole machine run (starting one per example would dominate)."""
    global _target, _root
    if _target is None:
        _root = Path(tempfile.mkdtemp(prefix="fresco-fuzz-"))
        _target = FuzzTarget(_root)
    return _target


class LiveBridge(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.t = target()

    @rule(data=st.binary(max_size=600), keep_open=st.booleans())
    def garbage(self, data: bytes, keep_open: bool) -> None:
        self.t.garbage(data, keep_open)

    @rule(sid=st.one_of(st.tuples(*[ints] * 11), st.tuples(*[small_ints] * 11),
                        st.integers(1, 64).map(valid_size_id)),
          vectors=st.lists(st.tuples(floats, floats, floats, floats, floats), max_size=4),
          keep_open=st.booleans())
    def frames(self, sid: tuple[int, ...], vectors: list[tuple[float, ...]],
               keep_open: bool) -> None:
        self.t.frames(sid, vectors, keep_open)

    @rule(disps=st.lists(hostile_disp, min_size=1, max_size=5),
          requests=st.lists(st.sampled_from([3, 5, 6, 7, 10, 12, 13, 14, 15, 42, 98, 99]),
                            min_size=1, max_size=5),
          commit=st.booleans(), vanish=st.booleans())
    def session(self, disps: list[float], requests: list[int], commit: bool,
                vanish: bool) -> None:
        self.t.session(disps, requests, commit, vanish)

    @rule(datagrams=st.lists(st.one_of(st.just(b"a"), st.binary(max_size=200)), max_size=5))
    def udp(self, datagrams: list[bytes]) -> None:
        self.t.udp(datagrams)

    # No precondition on the held connections: they outlive an example (one bridge for the
    # whole run), so a precondition on them made rule selection differ between a run and its
    # replay (hypothesis' FlakyStrategyDefinition). ``drop`` is a no-op when nothing is held.
    @rule(index=st.integers(0, 7), reset=st.booleans())
    def drop(self, index: int, reset: bool) -> None:
        self.t.drop(index, reset)

    @rule(command=st.sampled_from(["pause", "resume", "abort", "status"]),
          site=st.sampled_from(["fuzz", "fuzzu"]))
    def operator(self, command: str, site: str) -> None:
        self.t.operator(command, site)

    @invariant()
    def holds(self) -> None:
        self.t.check()


LiveBridge.TestCase.settings = settings(
    max_examples=20, stateful_step_count=12, deadline=None, derandomize=True,
    suppress_health_check=list(HealthCheck),
)
TestLiveBridge = LiveBridge.TestCase


def teardown_module() -> None:
    global _target
    if _target is not None:
        t, _target = _target, None
        print(f"fuzz: {t.inputs} inputs, {t.good_sessions} good sessions, "
              f"{len(t.sent)} commands forwarded; peak fds {t.peak_fds} "
              f"(baseline {t.baseline_fds}), peak RSS {t.peak_rss >> 20} MiB "
              f"(baseline {t.baseline_rss >> 20} MiB)")
        t.close()
    if _root is not None:
        shutil.rmtree(_root, ignore_errors=True)
