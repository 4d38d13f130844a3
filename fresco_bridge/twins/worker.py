"""The learner's worker process: one updater per twin, fed the source's committed steps, asked
for the twins' forces, strictly in the order the bridge saw the messages.

``LearnerState.handle`` is the whole behaviour (tested in process); ``worker_main`` only moves
messages between the queues. Source steps are keyed by ``(source session, step)`` and each
twin trial says how far it may learn (``through``, inclusive), so causality is exact whatever
order the client commits its elements in and whatever session it is: a source step is queued
when it arrives and learned only by a twin trial allowed to (``previous-step``: the twin's step
k of the source's session S answers from ``(S, k − 1)``; ``same-step`` from ``(S, k)``, the
bridge having sent it just before). Source-only sessions are learned from: every step of an
earlier source session lies before ``(S, ·)``, so the twin's next trial learns them.

Each twin has its own updater, fed the same observations: a twin cloned from another's updater
would not follow every updater's parameter changes (a UKF's retargeted Bilinear, an ANN's new
weights), and two seeded updaters fed the same steps hold the same parameters.

**A same-step answer learns the source's trial tentatively; training is on commits only.** A
same-step trial carries the source's measurement of the trial of step ``through`` (not
committed yet). The twin's updater learns it to answer (an updater can only predict from what
it has learned), having first taken a rollback point (``updating.base.snapshot``, the family
contract: no updater kind is special). When that step's commit arrives equal, the tentative
step was the committed one and stays learned; when it differs (an implicit scheme's
iterations), or a later trial does not allow it (the twin fell back to previous-step), the
updater returns to the rollback point and re-learns the committed steps since. The point is
kept while steps are learned and re-taken before a tentative step once ``REBASE`` committed
steps lie behind it: one snapshot per session's first same-step trial and one per ``REBASE``
steps after, and a re-learning bounded by ``REBASE`` steps. A trial catching up a backlog
(``twins/catchup.py``) learns a tentative step only once every committed step before it is
learned; short of that, it answers previous-step-like and says how far it learned.
"""

from __future__ import annotations

import bisect
import contextlib
import logging
import math
import multiprocessing
import multiprocessing.connection
import multiprocessing.queues
import os
import pickle
import queue
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from ..updating.base import Updater, UpdaterError, UpdaterInputError, restore, snapshot
from ..updating.registry import make_updater
from ..worker_output import forward_output

log = logging.getLogger("fresco_bridge.twins")

TRIM = 1024
"""Observations every twin has learned are dropped in chunks of at least this many (the
snapshots stay small)."""
NICE = 10
"""How much lower than the bridge the worker runs (``os.nice``)."""
REBASE = 64
"""Committed steps learned behind a twin's rollback point before the next tentative step takes
a new one: bounds the re-learning of a rollback (at ~1 ms a step, far inside the learner's
deadline) at one snapshot per this many same-step steps."""

Message = tuple[Any, ...]
"""``("observe", session, step, d, f)`` (a committed step),
``("trial", id, twin, d, (session, step)[, measured[, cap]])``: ``measured`` is ``(d, f)``, the
source's trial measurement of step ``(session, step)``, not committed yet (same-step: learned
tentatively), or None; ``cap`` is ``(steps, seconds)``: learn at most that many of the committed
steps it may and has not learned before, for at most that long past the first two
(``twins/catchup.py``), or None: all of them, as a replay must. A tentative step is learned only
once every committed step before it is. ``("commit", twin)``,
``("initial", id, twin)``, ``("sync", id)``, ``("snapshot", id)``, ``("learn", id, (session,
step))`` (background learning, no reply); ``None`` ends the worker."""
Reply = tuple[Any, ...]
"""``("trial", id, force, tangent, trained_through, update_seconds, one_step_error,
tentative, (session, step) learned through, unlearned)``: ``tentative``, the answer used the
source's trial measurement of step ``trained_through``, learned ahead of its commit; learned
through: the (session, step) the answer's model was learned through, the tentative step
included (what a replay of this trial asks for); ``unlearned``: the committed steps it asked for
and has not learned (catching up). ``("initial", id, tangent)``,
``("sync", id, trained_through)``, ``("snapshot", id, pickled
LearnerState)``, ``("error", id, reason)``, ``("ready",)``, ``("fatal", reason)``."""


@dataclass(frozen=True)
class TwinSpec:
    """One twin's updater: a registry name and its options (picklable)."""

    name: str
    updater: str
    options: dict[str, Any]
    on_loss: str = "hold"
    """``hold`` or ``freeze``: what the twin does when its learner is lost."""


@dataclass(frozen=True)
class LearnerSpec:
    """What the worker builds its updaters from (picklable: crosses the process boundary)."""

    source: str
    twins: tuple[TwinSpec, ...]


@dataclass
class _Twin:
    updater: Updater
    commits: int = 0
    applied: int = 0
    """How many of the source's observations this twin's updater has learned."""
    trained_through: int = 0
    """The source step of the last observation learned (0: none)."""
    update_seconds: float = 0.0
    """Wall time the updater spent learning the source step(s) learned for the twin's current
    step (0.0: none learned for it)."""
    one_step_error: float | None = None
    """The updater's one-step error on the last source step learned for the twin's current
    step (``Updater.last_one_step_error``; None: none learned, or not predicted)."""
    timed_step: int = -1
    """The twin step (its commits so far) ``update_seconds`` and ``one_step_error`` belong
    to."""
    learned: tuple[int, int] = (0, 0)
    """The (session, step) of the last committed observation applied (learned or rejected;
    a tentative step is not one)."""
    tentative: tuple[int, int, float, float] | None = None
    """``(session, step, d, F)``: the source's trial measurement learned ahead of its commit."""
    base: tuple[bytes, int, int, tuple[int, int]] | None = None
    """The rollback point: the updater's snapshot with ``applied``, ``trained_through`` and
    ``learned`` then (committed observations only behind it)."""
    since_base: int = 0
    """Committed observations learned since the rollback point."""
    wanted: tuple[int, int] = (0, 0)
    """How far the twin may learn in the background: the farthest ``through`` asked of it."""
    mid_step: bool = False
    """A trial since the last commit: nothing is learned in the background until the commit
    (a replay learns a step's steps at its committed trial: ``twins/catchup.py``)."""


@dataclass
class LearnerState:
    """The worker's state: the updaters, the source's observations, each twin's progress."""

    spec: LearnerSpec
    twins: dict[str, _Twin] = field(default_factory=dict)
    observations: list[tuple[int, int, float, float]] = field(default_factory=list)
    """``(source session, step, d, F)`` in the order the source committed them."""
    rejected: int = 0

    def __post_init__(self) -> None:
        for twin in self.spec.twins:
            self.twins[twin.name] = _Twin(make_updater(twin.updater, **twin.options))

    def handle(self, msg: Message) -> Reply | None:
        kind = msg[0]
        if kind == "observe":
            _, session, step, d, f = msg
            self.observations.append((int(session), int(step), float(d), float(f)))
            return None
        if kind == "commit":
            twin = self.twins[msg[1]]
            twin.updater.twin.commit()
            twin.commits += 1
            twin.mid_step = False
            return None
        if kind == "trial":
            rid, name, d, through = msg[1:5]
            key = (int(through[0]), int(through[1]))
            measured = msg[5] if len(msg) > 5 else None
            cap = msg[6] if len(msg) > 6 and msg[6] is not None else (None, None)
            twin = self._learned(name, key, measured, limit=cap[0], budget=cap[1])
            twin.mid_step, twin.wanted = True, max(twin.wanted, key)
            try:
                force, tangent = twin.updater.twin.set_trial(float(d))
            except (ValueError, ArithmeticError) as exc:
                return ("error", rid, f"the twin cannot answer trial d = {d!r}: {exc}")
            if not (math.isfinite(force) and math.isfinite(tangent)):
                return ("error", rid, f"the twin answered non-finite force {force!r} / tangent "
                        f"{tangent!r} at d = {d!r}")
            used = twin.tentative is not None and twin.tentative[:2] == key
            return ("trial", rid, force, tangent, twin.trained_through, twin.update_seconds,
                    twin.one_step_error, used,
                    twin.learned if twin.tentative is None else twin.tentative[:2],
                    self._unlearned(twin, key))
        if kind == "initial":
            _, rid, name = msg
            return ("initial", rid, float(self.twins[name].updater.twin.initial_tangent))
        if kind == "snapshot":
            try:
                return ("snapshot", msg[1], pickle.dumps(self, pickle.HIGHEST_PROTOCOL))
            except (pickle.PicklingError, AttributeError, TypeError) as exc:
                return ("error", msg[1], f"no snapshot: the updaters do not pickle ({exc})")
        if kind == "learn":  # steps no twin can ask for later: learned in the background
            key = (int(msg[2][0]), int(msg[2][1]))
            for twin in self.twins.values():
                twin.wanted = max(twin.wanted, key)
            return None
        if kind == "sync":
            through = min((t.trained_through for t in self.twins.values()), default=0)
            return ("sync", msg[1], through)
        raise ValueError(f"unknown learner message {kind!r}")

    def learn_in_background(self) -> bool:
        """One source step learned for each twin between its steps that may learn it
        (``wanted``); whether any such step is left (``twins/catchup.py``). A commit met there
        confirms a tentative step or rolls back to its point, as in a trial."""
        left = False
        for name, twin in self.twins.items():
            if twin.mid_step or self._unlearned(twin, twin.wanted) == 0:
                continue
            self._learned(name, twin.wanted, timed=False, limit=1)
            left = left or self._unlearned(twin, twin.wanted) > 0
        return left

    def _unlearned(self, twin: _Twin, through: tuple[int, int]) -> int:
        """The committed source steps up to ``through`` the twin has not learned yet."""
        obs, n = self.observations, twin.applied
        if n >= len(obs) or obs[n][:2] > through:
            return 0
        return bisect.bisect_right(obs, through, lo=n, key=_key) - n

    def _learned(self, name: str, through: tuple[int, int],
                 measured: tuple[float, float] | None = None, *, timed: bool = True,
                 limit: int | None = None, budget: float | None = None) -> _Twin:
        """Twin ``name`` with every committed source step up to ``through`` ((session, step),
        inclusive) learned, or the first ``limit`` of those it had not learned, stopping once
        ``budget`` seconds are spent past the first two (steps re-learned after a rollback
        count for neither: it had learned them); then, with ``measured`` (the source's trial
        measurement of step ``through``, not committed yet) and nothing committed before it
        left unlearned, that one tentatively (``timed``: for a trial, whose update time it
        is)."""
        twin = self.twins[name]
        obs = self.observations
        if timed and twin.timed_step != twin.commits:  # a new twin step: its own update time
            twin.timed_step, twin.update_seconds, twin.one_step_error = twin.commits, 0.0, None
        before = twin.applied
        tent = twin.tentative
        if tent is not None and (tent[:2] > through or (
                measured is not None and tent[:2] == through and tent[2:] != tuple(measured))):
            self._roll_back(twin)  # the trial does not allow it: previous-step, or another read
        end = len(obs) if limit is None else min(len(obs), before + limit)
        stop = None if budget is None else time.perf_counter() + budget
        while twin.applied < end and obs[twin.applied][:2] <= through:
            if stop is not None and twin.applied - before >= 2 and time.perf_counter() > stop:
                break
            session, step, d, f = obs[twin.applied]
            tent = twin.tentative
            if tent is not None and tent[:2] == (session, step):
                if tent[2:] != (d, f):  # the commit is not the trial learned: back, re-learn
                    self._roll_back(twin)
                    continue
                twin.tentative = None  # the trial learned was the committed step
                twin.applied += 1
                twin.learned = (session, step)
                twin.since_base += 1
                continue
            twin.applied += 1
            twin.learned = (session, step)
            twin.since_base += 1
            self._observe(twin, step, d, f, timed=timed)
        if twin.tentative is None and twin.base is not None and twin.since_base >= REBASE:
            twin.base = None  # taken again before the next tentative step (trimming goes on)
        if measured is not None and twin.tentative is None and twin.learned < through \
                and self._unlearned(twin, through) == 0:  # only behind every committed step
            if twin.base is None:
                twin.base = (snapshot(twin.updater), twin.applied, twin.trained_through,
                             twin.learned)
                twin.since_base = 0
            if self._observe(twin, through[1], float(measured[0]), float(measured[1]),
                             timed=timed):
                twin.tentative = (*through, float(measured[0]), float(measured[1]))
        self._trim()
        return twin

    def _observe(self, twin: _Twin, step: int, d: float, f: float, *, timed: bool) -> bool:
        try:
            twin.updater.observe(d, f)
        except UpdaterInputError as exc:
            self.rejected += 1
            log.warning("learner: source step %d not learned: %s", step, exc)
            return False
        twin.trained_through = step
        if timed:
            twin.update_seconds += twin.updater.last_update_seconds
            twin.one_step_error = twin.updater.last_one_step_error
        return True

    def committed_only(self) -> None:
        """Every twin back to the committed steps it learned (a tentative step unlearned):
        a copy that will not see the source's commits (the learner's frozen copy)."""
        for twin in self.twins.values():
            if twin.tentative is not None:
                self._roll_back(twin)

    @staticmethod
    def _roll_back(twin: _Twin) -> None:
        """The twin's updater as at its rollback point: the tentative step unlearned, the
        committed steps since to be learned again."""
        assert twin.base is not None, "a tentative step is learned after a rollback point"
        blob, twin.applied, twin.trained_through, twin.learned = twin.base
        twin.updater = restore(blob)
        twin.tentative = None
        twin.since_base = 0

    def _trim(self) -> None:
        """Drop what every twin has learned and no rollback point needs, in chunks."""
        obs = self.observations
        learned = min((t.applied if t.base is None else min(t.applied, t.base[1])
                       for t in self.twins.values()), default=0)
        if learned >= TRIM:
            del obs[:learned]
            for t in self.twins.values():
                t.applied -= learned
                if t.base is not None:
                    t.base = (t.base[0], t.base[1] - learned, *t.base[2:])


def _key(obs: tuple[int, int, float, float]) -> tuple[int, int]:
    return obs[0], obs[1]


def worker_main(spec: LearnerSpec, inbox: multiprocessing.queues.Queue[list[Message] | None],
                outbox: multiprocessing.queues.Queue[Reply], start: bytes | None = None) -> None:
    """The worker process: build (or start from the snapshot ``start``), say ready, then
    answer batches of messages in order until ``None`` (or until the bridge process is gone).
    It runs at a lower priority and with one BLAS thread, so training takes the CPU the
    bridge's step loop leaves."""
    end_output = forward_output(outbox.put)  # its warnings and stderr: lines of the log
    try:
        _end_with_the_bridge()
        with contextlib.suppress(OSError):
            os.nice(NICE)
        limits = _one_blas_thread()
        try:
            state = LearnerState(spec) if start is None else pickle.loads(start)
        except (UpdaterError, OSError, ValueError, pickle.UnpicklingError) as exc:
            outbox.put(("fatal", f"the learner of {spec.source} could not build its updaters: "
                        f"{exc}"))
            return
        outbox.put(("ready",))
        parent = multiprocessing.parent_process()
        background = False
        while True:
            try:
                batch = inbox.get_nowait() if background else inbox.get(timeout=1.0)
            except queue.Empty:
                if background:  # nothing asked: a step of the backlog, then look again
                    background = state.learn_in_background()
                elif parent is not None and not parent.is_alive():
                    break  # the bridge was killed: no orphan worker
                continue
            if batch is None:
                break
            for msg in batch:
                reply = _handled(state, msg)
                if reply is not None:
                    outbox.put(reply)
            background = True  # whether there is anything to learn: the next empty inbox says
        del limits
    finally:
        end_output()  # its last lines of fd 2 before the channel closes


def _end_with_the_bridge() -> None:
    """A thread that ends this process the moment the bridge's process is gone, however it
    ended (``kill -9`` included) and whatever the worker is doing (a long refit, a backlog of
    batches): it waits on the parent's sentinel, which the kernel closes at the parent's
    death. Nothing of the worker's state outlives its bridge (the record is the bridge's)."""
    parent = multiprocessing.parent_process()
    if parent is None:
        return

    def watch() -> None:
        multiprocessing.connection.wait([parent.sentinel])
        os._exit(0)

    threading.Thread(target=watch, name="bridge-watch", daemon=True).start()


def _handled(state: LearnerState, msg: Message) -> Reply | None:
    try:
        return state.handle(msg)
    except Exception as exc:  # an updater bug must not kill the twin silently
        rid = msg[1] if msg[0] in ("trial", "initial", "sync", "snapshot", "learn") else None
        return ("error", rid, f"{type(exc).__name__}: {exc}")


def _one_blas_thread() -> Any:
    """Limit numpy's BLAS to one thread in this process (threadpoolctl, when installed)."""
    try:
        from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]
    except ImportError:
        return None
    return threadpool_limits(1)
