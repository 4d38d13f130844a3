"""The learner of one source site, on the bridge's side: its worker process (through a
``WorkerChannel``, ``channel.py``), the messages to it and its answers, never blocking the
event loop.

Messages go out in batches, one per request (a twin's trial): what changes the worker's state
(the source's steps, the twins' commits) waits in a list until then, so the source's step
costs no IPC. Every wait has a deadline; a missed deadline or a dead worker is a *learner
loss*. A twin whose rule is ``hold`` then fails (``LearnerError``: its site HOLDs); one whose
rule is ``freeze`` answers from a local copy: the worker's last pickled snapshot (taken at
start and every ``SNAPSHOT_EVERY`` twin steps) with the twins' commits since replayed, learning
nothing more. The worker is replaced and caught up by replaying the ordered log of what
changes its state (the source's steps, each twin's committed trial), and the learner is live
again once the new worker has answered past the end of that log.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import math
import pickle
from collections.abc import Callable
from typing import Any

from ..site_output import CommittedStep, SiteNotice
from ..telemetry.schema import SiteStatus
from ..worker_output import OUTPUT, relay_output
from .catchup import CatchUpEvents, trial_cap
from .channel import WorkerChannel
from .checkpoint import Checkpoint, CheckpointWriter, history_counts, resume_point
from .worker import LearnerSpec, LearnerState, Message, Reply

log = logging.getLogger("fresco_bridge.twins")

START_DEADLINE = 120.0
"""Seconds a new worker may take to import, read its data and build its updaters."""
SNAPSHOT_EVERY = 50
"""Twin steps between two snapshots of the worker when a twin may freeze
(``on_learner_loss = "freeze"``: the frozen copy starts from the last one)."""
CHECKPOINT_EVERY = 2000
"""Messages to the worker between two snapshots otherwise: a new worker starts from the last
one and replays only what came after it, and the log behind it is dropped (memory bounded).
A snapshot this many messages past the last one written is also the run directory's
checkpoint (``checkpoint.py``): ``--resume`` starts from it."""
LEARN_AHEAD = 64
"""Source steps committed while no twin of the source is in a session, sent to the worker to
be learned at once in batches of this many (a twin's next trial finds them learned)."""

Measured = tuple[float, float] | None
"""The source's measurement (d, F) of the trial of a twin's step, not committed yet: a
same-step trial's (``worker.py``: learned tentatively, trained on only if committed)."""

EventSink = Callable[[str, str, dict[str, object]], None]
"""``(kind, reason, extra)``: an event for the twin sites of this learner."""


class LearnerError(Exception):
    """The learner cannot answer (lost, catching up, or the twin refused the trial)."""


class Learner:
    """One source site's learner: a worker process with one updater per twin."""

    def __init__(self, source: str, spec: LearnerSpec, *, deadline: float) -> None:
        self.source = source
        self.spec = spec
        self.deadline = deadline
        self.state = "stopped"
        """``starting``, ``live``, ``lost``, ``catching-up`` or ``stopped``."""
        self.reason = ""
        self.source_step = 0
        self.trained_through = 0
        self.not_trained = 0
        """Source steps with a non-finite measurement, never sent for training."""
        self.losses = 0
        self.log: list[Message] = []
        """What changed the worker's state since the last snapshot, in order: replayed to a
        new worker started from that snapshot."""
        self._log_base = 0
        """The absolute position of ``log[0]`` (what the snapshots dropped before it)."""
        self._asked_at = 0
        """The absolute log position of the last snapshot asked."""
        self._ahead = 0
        self.twins_active: Callable[[], bool] = lambda: True
        """Whether a twin of this source is in a session (set by the wiring); while none is,
        the source's steps are learned as they come (``LEARN_AHEAD``)."""
        self.source_session = 0
        """The source's current (or last) session: a twin's trial may learn every step of
        the sessions before it (source-only sessions are learned from)."""
        self._last_trial: dict[str, tuple[float, tuple[int, int], Measured]] = {}
        """Each twin's last trial: its displacement, how far it learned ((session, step),
        inclusive) and the source's trial measurement it was given (same-step)."""
        self._through: dict[str, int] = {}
        """The source step each twin's last live answer was learned through."""
        self._tentative: dict[str, bool] = {}
        """Whether each twin's last answer used its source's trial measurement (same-step,
        learned ahead of the source's commit)."""
        self._used: dict[tuple[int, int], tuple[str, float, float]] = {}
        """Source steps whose trial measurement a twin's committed answer used, until the
        source's commit of that step says whether it was the committed one."""
        self._last_committed: tuple[int, int, float, float] = (0, 0, math.nan, math.nan)
        """The source's last committed (session, step, d, F)."""
        self._sinks: list[EventSink] = []
        self.catch_up = CatchUpEvents(source, self._event)
        self._ids = itertools.count(1)
        self._pending: dict[int, asyncio.Future[Any]] = {}
        self._held: list[Message] = []
        """Messages for the worker that wait for its next request (``_send``)."""
        self._restart: asyncio.Task[None] | None = None
        self._channel: WorkerChannel | None = None
        self._ready: asyncio.Future[None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._closing = False
        self.update_observer: Callable[[float], None] | None = None
        """Takes the worker's update time of each newly learned step (the metrics)."""
        self._freezes = {t.name for t in spec.twins if t.on_loss == "freeze"}
        self._commits = 0
        self._snapshot: tuple[int, int, bytes] | None = None
        """(log length, twin steps, pickled worker state) of the last snapshot."""
        self._snapshot_asked: dict[int, tuple[int, int, int, dict[str, int]]] = {}
        """Snapshots asked: (log position, twin steps, observations, each twin's commits)."""
        self._observed, self._committed = 0, dict[str, int]()
        self.checkpoints: CheckpointWriter | None = None
        self._written_at = 0
        """The log position of the last snapshot offered as a checkpoint."""
        self._answered_locally: set[str] = set()
        """Twins whose last trial the local copy answered (a new worker has not seen it)."""
        self._local: LearnerState | None = None
        """The frozen copy answering ``freeze`` twins while the worker is lost."""

    @property
    def snapshot_step(self) -> int:
        """Twin steps committed when the last snapshot was taken (-1: none yet)."""
        return -1 if self._snapshot is None else self._snapshot[1]

    def preload(self, log_: list[Message], *, source_step: int, commits: int,
                checkpoint: Checkpoint | None = None) -> None:
        """Start from a recorded history (``serve --resume``): the worker starts from
        ``checkpoint`` (if the history reaches it) and replays the rest of ``log_`` before it
        answers, as a new worker after a loss does."""
        rest = resume_point(self.source, log_, checkpoint)
        if rest is not None and checkpoint is not None:
            self._snapshot = (0, checkpoint.twin_steps, checkpoint.state)
        self.log = list(log_) if rest is None else rest
        self._log_base = self._written_at = 0
        self._observed, counts = history_counts(log_)
        self._committed = dict(counts)
        self.source_step = source_step
        self._commits = commits

    def add_event_sink(self, sink: EventSink) -> None:
        self._sinks.append(sink)

    def _event(self, kind: str, reason: str, **extra: object) -> None:
        for sink in self._sinks:
            sink(kind, reason, extra)

    @property
    def pid(self) -> int | None:
        return None if self._channel is None else self._channel.pid

    # -- the worker's life ------------------------------------------------------------------
    async def start(self) -> None:
        """Start the worker and wait (``START_DEADLINE``) until its updaters are built."""
        self._loop = asyncio.get_running_loop()
        self.state = "starting"
        await self._spawn()
        if self.log or self._snapshot is not None:  # a resumed run: the record, first
            self.state = "catching-up"
            self._held = list(self.log)
            (through,) = await self._request(("sync",), START_DEADLINE)
            self.trained_through = int(through)
        self.state = "live"
        self._ask_snapshot()
        log.info("learner of %s: worker %s live (twins %s)", self.source, self.pid,
                 ", ".join(f"{t.name}: {t.updater}" for t in self.spec.twins))

    async def _spawn(self) -> None:
        assert self._loop is not None
        start = None if self._snapshot is None else self._snapshot[2]
        self._ready = self._loop.create_future()
        self._held.clear()  # in the log: a new worker gets them with the replay
        self._channel = WorkerChannel(self.spec, start, on_reply=self._answer,
                                      on_exit=self._died)
        await self._channel.start()
        try:
            await asyncio.wait_for(asyncio.shield(self._ready), START_DEADLINE)
        except TimeoutError:
            raise LearnerError(f"learner of {self.source}: the worker was not ready within "
                               f"{START_DEADLINE:g} s") from None

    def _died(self, code: int | None) -> None:
        if self._closing:
            return
        reason = f"the worker process exited (code {code})"
        if self._ready is not None and not self._ready.done():
            self._ready.set_exception(LearnerError(reason))
        else:
            self._lose(reason)

    def _answer(self, reply: Reply) -> None:
        kind = reply[0]
        if kind == OUTPUT:  # a line the worker logged or printed
            relay_output(self.source, self.pid, reply)
            return
        if kind == "ready":
            if self._ready is not None and not self._ready.done():
                self._ready.set_result(None)
            return
        if kind == "fatal":
            if self._ready is not None and not self._ready.done():
                self._ready.set_exception(LearnerError(reply[1]))
            else:
                self._lose(reply[1])
            return
        asked = self._snapshot_asked.pop(reply[1], None)
        if asked is not None:
            if kind == "snapshot":
                position, steps, observed, committed = asked
                self._snapshot = (position, steps, reply[2])
                self._trim(position)
                if self.checkpoints is not None \
                        and position - self._written_at >= CHECKPOINT_EVERY:
                    self._written_at = position
                    self.checkpoints.offer(Checkpoint(observed, committed, steps, reply[2]))
            else:
                log.error("learner of %s: %s; freeze answers from an older snapshot or HOLDs",
                          self.source, reply[2])
            return
        fut = self._pending.pop(reply[1], None)
        if fut is None or fut.done():
            if kind == "error":
                log.error("learner of %s: %s", self.source, reply[2])
            return  # an answer to a replayed message, or one whose wait ended
        if kind == "error":
            fut.set_exception(LearnerError(reply[2]))
        else:
            fut.set_result(reply[2:])

    def _lose(self, reason: str) -> None:
        """The worker is gone or silent: fail what waits, tell the twins, replace it."""
        if self.state in ("lost", "stopped") or self._closing:
            return
        self.state, self.reason = "lost", reason
        self.losses += 1
        log.error("learner of %s LOST: %s; its twins HOLD, a new worker catches up",
                  self.source, reason)
        for fut in self._pending.values():
            if not fut.done():
                fut.set_exception(LearnerError(f"learner lost: {reason}"))
        self._pending.clear()
        self._event("learner-lost", f"learner of {self.source} lost: {reason}",
                    losses=self.losses)
        if self._freezes:
            self._freeze()
        assert self._loop is not None
        self._restart = self._loop.create_task(self._replace(), name=f"learner.{self.source}")

    async def _replace(self) -> None:
        """A new worker, caught up by replaying the log, then live again."""
        await self._stop_worker(kill=True)
        try:
            await self._spawn()
        except LearnerError as exc:
            self.reason = str(exc)
            log.error("learner of %s: no new worker: %s", self.source, exc)
            return
        self.state = "catching-up"
        self._held = list(self.log)
        try:
            await self._request(("sync",), START_DEADLINE)
        except LearnerError as exc:
            self._lose(f"catching up failed: {exc}")
            return
        self.state, self.reason, self._local = "live", "", None
        log.warning("learner of %s: a new worker (%s) caught up over %d message(s); live",
                    self.source, self.pid, len(self.log))
        self._event("learner-restored", f"learner of {self.source} live again (worker "
                    f"restarted, {len(self.log)} message(s) replayed)", losses=self.losses,
                    live_from_twin_step=self._commits // len(self.spec.twins) + 1)
        self._ask_snapshot()

    def _ask_snapshot(self) -> None:
        """Ask the worker for a snapshot of its state: where a new worker starts, and the
        frozen copy of ``freeze`` twins."""
        rid = next(self._ids)
        self._snapshot_asked[rid] = (self._log_base + len(self.log),
                                     self._commits // len(self.spec.twins), self._observed,
                                     dict(self._committed))
        self._asked_at = self._log_base + len(self.log)
        self._put(("snapshot", rid))

    def _learn_ahead(self, through: tuple[int, int]) -> None:
        """Let the worker learn through ``through`` in the background (no answer: a trial
        never waits for it, ``twins/catchup.py``)."""
        self._put(("learn", 0, through))

    def _trim(self, position: int) -> None:
        """The snapshot covers the log up to ``position`` (absolute): drop what is behind."""
        cut = position - self._log_base
        if cut > 0:
            del self.log[:cut]
            self._log_base = position

    def _maybe_checkpoint(self) -> None:
        if (self.state == "live"
                and self._log_base + len(self.log) - self._asked_at >= CHECKPOINT_EVERY):
            self._ask_snapshot()

    def _freeze(self) -> None:
        """The local copy for ``freeze`` twins: the last snapshot, the twins' commits since
        replayed (trials and commits only: it learns nothing more)."""
        if self._snapshot is None:
            self._event("learner-frozen", f"learner of {self.source}: no snapshot to freeze "
                        "from; its freeze twins fail (HOLD) until a new worker catches up",
                        frozen=False)
            return
        position, steps, data = self._snapshot
        local: LearnerState = pickle.loads(data)
        local.committed_only()  # it sees no more commits: a tentative step is unlearned
        for msg in self.log[position - self._log_base:]:
            if msg[0] != "observe":
                local.handle(msg[:5])  # a trial without its tentative step: learns nothing
        self._local = local
        through = min((t.trained_through for t in local.twins.values()), default=0)
        log.warning("learner of %s: freeze twins answer from the snapshot of twin step %d "
                    "(source trained through step %d), frozen", self.source, steps, through)
        self._event("learner-frozen", f"learner of {self.source}: freeze twins answer from "
                    f"the snapshot of twin step {steps}, parameters frozen (source trained "
                    f"through step {through})", frozen=True, snapshot_step=steps,
                    trained_through=through)

    async def _stop_worker(self, *, kill: bool) -> None:
        channel, self._channel = self._channel, None
        if channel is not None:
            await channel.stop(kill=kill)

    async def close(self) -> None:
        """Stop the worker (a clean end, then a kill past ``STOP_DEADLINE``)."""
        self._closing = True
        self.state = "stopped"
        task = self._restart
        if task is not None and not task.done():
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        await self._stop_worker(kill=False)
        if self.checkpoints is not None:
            await self.checkpoints.close()
        for fut in self._pending.values():
            if not fut.done():
                fut.set_exception(LearnerError("the bridge is stopping"))

    # -- messages -----------------------------------------------------------------------------
    def _put(self, msg: Message) -> None:
        """``msg`` (a request) to the worker, after everything held before it; never blocks."""
        batch, self._held = [*self._held, msg], []
        if self._channel is not None:
            self._channel.post(batch)

    def _send(self, msg: Message) -> None:
        """A message that changes the worker's state: logged, and held for the worker's next
        request unless a new worker is being started (the replay of the log will carry it).
        The worker needs the source's steps and the twins' commits only before its next
        answer, so the source's committed step costs the step loop an append, no IPC."""
        self.log.append(msg)
        if msg[0] == "observe":
            self._observed += 1
        elif msg[0] == "commit":
            self._committed[msg[1]] = self._committed.get(msg[1], 0) + 1
        if self.state in ("live", "catching-up"):
            self._held.append(msg)

    async def _request(self, msg: Message, deadline: float) -> tuple[Any, ...]:
        assert self._loop is not None
        rid = next(self._ids)
        fut: asyncio.Future[tuple[Any, ...]] = self._loop.create_future()
        self._pending[rid] = fut
        self._put((msg[0], rid, *msg[1:]))
        try:
            return await asyncio.wait_for(fut, deadline)
        except TimeoutError:
            self._pending.pop(rid, None)
            reason = f"no answer to {msg[0]} within {deadline:g} s"
            self._lose(reason)
            raise LearnerError(f"learner lost: {reason}") from None

    def step_committed(self, step: CommittedStep) -> None:
        """The source site's listener: its committed (d, F) to the worker (never a NaN)."""
        d, f = step.daq_disp[0], step.daq_force[0]
        self.source_step, self.source_session = step.step, step.session
        self._last_committed = (step.session, step.step, d, f)
        if self._used:  # a source step whose trial a twin's committed answer used
            used = self._used.pop((step.session, step.step), None)
            if used is not None:
                self._check_used(used[0], (step.session, step.step), used[1:], (d, f))
            for key in [k for k in self._used if k < (step.session, step.step)]:
                del self._used[key]  # never committed (the source held): nothing to check
        if not (math.isfinite(d) and math.isfinite(f)):
            self.not_trained += 1
            log.warning("learner of %s: step %d has a non-finite measurement (d %r, F %r); not "
                        "trained on", self.source, step.step, d, f)
            self._event("not-trained", f"source {self.source} step {step.step}: non-finite "
                        f"measurement (d {d!r} mm, F {f!r} kN) not trained on",
                        source_step=step.step)
            return
        self._send(("observe", step.session, step.step, d, f))
        if not self.twins_active():  # nobody can ask for it later than now: learn it now
            self._ahead += 1
            if self._ahead >= LEARN_AHEAD and self.state == "live":
                self._ahead = 0
                self._learn_ahead((step.session, step.step))
        self._maybe_checkpoint()

    def site_event(self, notice: SiteNotice, status: SiteStatus) -> None:
        """The source's events: a session that opens is the session its twins learn up to."""
        if notice.kind == "session-open":
            self.source_session = notice.session

    def _check_used(self, twin: str, key: tuple[int, int], used: tuple[float, float],
                    committed: tuple[float, float]) -> None:
        """A twin's committed answer used the source's trial measurement of step ``key``:
        a commit that differs makes its update line's ``through`` a trial's, said once in
        an event (the updater itself went back to the committed measurement)."""
        if used == committed:
            return
        log.warning("learner of %s: twin %s answered source step %d with its trial "
                    "measurement (d %r, F %r); the committed one is (%r, %r)", self.source,
                    twin, key[1], *used, *committed)
        self._event("same-step-mismatch", f"twin {twin}: its answer used source {self.source}"
                    f"'s trial of step {key[1]}, whose commit differs (a later trial of that "
                    "step came after the twin's answer); trained on the committed one",
                    source_step=key[1])

    def through(self, step: int, *, same_step: bool) -> tuple[int, int]:
        """How far a twin's trial at its ``step`` may learn: the source's steps of earlier
        sessions, and of its current session those before ``step`` (with ``same_step``,
        ``step`` too)."""
        return (self.source_session, step if same_step else step - 1)

    async def trial(self, twin: str, d: float, *, step: int, same_step: bool = False,
                    measured: Measured = None
                    ) -> tuple[float, float, int, float, float | None, tuple[int, int] | None]:
        """The twin's (force, tangent) at ``d`` (its ``step``), the source step it learned
        through, the update time, the source's one-step error of the twin's current step
        (``LearnerState``) and the source (session, step) it was learned through when that is
        short of what it asked for (catching up: ``twins/catchup.py``; else None). With
        ``same_step`` it learns the source's step ``step`` too: the committed one, or
        ``measured``, that step's trial measurement, learned tentatively (trained on only if
        it is the one committed; not learned while committed steps before it are not)."""
        through = self.through(step, same_step=same_step or measured is not None)
        if self.state != "live":
            return self._frozen_trial(twin, d, through)
        self._last_trial[twin] = (d, through, measured)
        self._answered_locally.discard(twin)
        msg: Message = ("trial", twin, d, through, measured)
        try:
            force, tangent, trained, seconds, error, tentative, upto, behind = \
                await self._request((*msg, trial_cap(self.deadline)), self.deadline)
        except LearnerError:
            if self.state == "live":  # the twin refused this trial: no loss
                raise
            return self._frozen_trial(twin, d, through)
        if int(trained) > self._through.get(twin, 0) and self.update_observer is not None:
            self.update_observer(float(seconds))  # each twin's newly learned step(s), once
        self._through[twin] = self.trained_through = int(trained)
        self._tentative[twin] = bool(tentative)
        upto = (int(upto[0]), int(upto[1]))
        self._last_trial[twin] = (d, upto, measured if tentative else None)  # what a replay
        # learns: exactly what this answer did (its tentative step only if it used it)
        self.catch_up.answered(twin, step, int(behind), upto)
        return (float(force), float(tangent), self.trained_through, float(seconds), error,
                upto if behind else None)

    def _frozen(self, twin: str) -> LearnerState:
        """The local copy, if twin ``twin`` may answer from it; else LearnerError."""
        if twin not in self._freezes or self._local is None:
            raise LearnerError(f"learner of {self.source} is {self.state}"
                               + (f" ({self.reason})" if self.reason else ""))
        return self._local

    def _frozen_trial(self, twin: str, d: float, through: tuple[int, int]
                      ) -> tuple[float, float, int, float, float | None, tuple[int, int] | None]:
        local = self._frozen(twin)
        self._answered_locally.add(twin)
        reply = local.handle(("trial", 0, twin, d, through))
        assert reply is not None
        if reply[0] == "error":
            raise LearnerError(reply[2])
        self._last_trial[twin] = (d, through, None)  # a new worker learns as if never lost
        return float(reply[2]), float(reply[3]), int(reply[4]), float(reply[5]), reply[6], None

    def commit(self, twin: str) -> None:
        """The twin's last trial becomes its committed state."""
        d, through, measured = self._last_trial.get(twin, (0.0, (0, 0), None))
        trial: Message = ("trial", 0, twin, d, through, measured)
        if self._tentative.pop(twin, False) and measured is not None and self.state == "live":
            if self._last_committed[:2] == through:  # the source committed it first
                self._check_used(twin, through, measured, self._last_committed[2:])
            else:
                self._used[through] = (twin, *measured)
        if self.state == "live" and twin not in self._answered_locally:
            self.log.append(trial)  # the live worker has it; a replay needs it before the commit
        else:
            if self.state != "live":
                self._frozen(twin).handle(("commit", twin))
            self._send(trial)  # answered locally: the worker has not seen this trial
        self._send(("commit", twin))
        self._commits += 1
        if self.state == "live" and self.catch_up.behind(twin) and self._channel is not None:
            self._channel.post(self._held)  # the commit now: the backlog is learned meanwhile
            self._held = []
        if self._freezes and self.state == "live" \
                and self._commits % (SNAPSHOT_EVERY * len(self.spec.twins)) == 0:
            self._ask_snapshot()
        else:
            self._maybe_checkpoint()

    async def initial(self, twin: str) -> float:
        if self.state != "live":
            reply = self._frozen(twin).handle(("initial", 0, twin))
            assert reply is not None
            return float(reply[2])
        (tangent,) = await self._request(("initial", twin), self.deadline)
        return float(tangent)

    def status(self, twin: str, *, active: bool = True) -> dict[str, object]:
        """Twin ``twin``'s view of its learner (``ctl status``). ``behind`` only while the
        twin's session is ``active`` (after a run the last source steps wait, unlearned, for a
        trial that never comes); a frozen twin says the step its snapshot was trained through."""
        trained = self.trained_through
        behind = self.source_step - trained - 1
        shown = self.state if self.state != "live" or behind <= 0 or not active \
            else f"behind {behind}"
        if self.state != "live" and twin in self._freezes and self._local is not None:
            shown = "frozen"
            trained = self._local.twins[twin].trained_through
        return {"learner": shown, "learner_reason": self.reason or None,
                "steps_trained": trained, "source_step": self.source_step,
                "not_trained": self.not_trained, "learner_losses": self.losses,
                "worker_pid": self.pid}
