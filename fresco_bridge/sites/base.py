"""The ``Site`` protocol: what the transports (``server/``) and the operator desk (``ctl.py``)
need of a site, and nothing more.

Every site kind (``site_kinds.py``) implements it, and is served, refused, paused, aborted,
recorded and published the same way; nothing outside a kind's module knows more of a site.
"""

from __future__ import annotations

from collections.abc import Callable, Coroutine
from typing import TYPE_CHECKING, Any, Protocol, TypeAlias, TypeVar

from protocol import Signals, SignalSizes

from .site_config import SiteConfigBase

if TYPE_CHECKING:
    from ..record.site import SiteRecorder
    from ..telemetry.metrics import SiteMetrics
    from ..telemetry.schema import CorrectionSample, SiteStatus
    from .access import RejectionLog
    from .listeners import EventListener, StepListener

__all__ = ["Later", "Site", "SiteError"]

T = TypeVar("T")
Later: TypeAlias = Coroutine[Any, Any, T]
"""What is left of a request that must wait (controller I/O, an operator): await it."""


class SiteError(Exception):
    """A session cannot be served by this site (sizes that do not fit, site busy, aborted)."""


class Site(Protocol):
    """A site as a transport and an operator see it (OpenFresco's *experimental site*)."""

    name: str
    cfg: SiteConfigBase

    @property
    def session(self) -> int:
        """Number of the current (or last) integrator session."""
        ...

    pending: tuple[float, ...] | None
    """A command waiting inside a request (operator pause, controller recovery), or None."""
    damping: tuple[float, ...]
    mass: tuple[float, ...]
    """Column-major n×n matrices answering actions 14 and 15."""
    metrics: SiteMetrics | None
    rejections: RejectionLog | None
    step: int
    """The last committed step (of the current or last session)."""
    time: float
    trial: Signals
    """The current trial (element side, basic DOFs)."""

    @property
    def in_session(self) -> bool: ...

    recorder: SiteRecorder | None
    """The one writer of this site's lines in the run record (None: recording off)."""

    @property
    def busy(self) -> bool:
        """A client holds the site: its session is open (one client per site)."""
        ...

    # -- sessions (the transports, the protocol handlers) --------------------------------------
    def claim(self, peer: str) -> None:
        """``peer`` connected: raise :class:`SiteError` if the site cannot take a session now
        (busy, a state that accepts none, a run record that cannot be written). Nothing is held
        nor recorded: the site is the client's from ``open_session`` (its sizes fit) on."""
        ...

    def open_session(self, peer: str) -> int:
        """``peer`` introduced itself (sizes that fit): its session opens (its number)."""
        ...

    def close_session(self, reason: str, *, error: bool = False) -> bool:
        """End the session (True); False if none is open."""
        ...

    def attach_session_end(self, end: Callable[[str], None]) -> None:
        """How the site itself ends the open session (operator abort, deadline)."""
        ...

    def check_sizes(self, ctrl: SignalSizes, daq: SignalSizes, who: str) -> None:
        """Raise :class:`SiteError` if the client's signal sizes do not fit the site."""
        ...

    def record_refusal(self, message: str, **extra: object) -> None:
        """A refused connection, into the site's record (the transport counts and logs it)."""
        ...

    # -- the step (the protocol handlers) ------------------------------------------------------
    # ``*_eager``: done at once when the site can (its result, or None), else the coroutine
    # that finishes the request (``Later``); the coroutines are the same requests, awaited.
    def set_trial_eager(self, trial: Signals) -> Later[None] | None: ...

    def commit_eager(self) -> Later[None] | None: ...

    def out_signals_eager(self, sizes: SignalSizes) -> Signals | Later[Signals]: ...

    def tangent_eager(self) -> tuple[float, ...] | Later[tuple[float, ...]]: ...

    async def set_trial(self, trial: Signals) -> None: ...

    async def commit(self) -> None: ...

    async def out_signals(self, sizes: SignalSizes) -> Signals: ...

    async def tangent(self) -> tuple[float, ...]: ...

    async def initial(self) -> tuple[float, ...]: ...

    def stopping(self) -> bool:
        """The integrator is being told to stop: every answer of the session is NaN."""
        ...

    # -- the operator (ctl.py: control socket, MQTT commands) ----------------------------------
    def operator_pause(self, source: str) -> str: ...

    def operator_resume(self, source: str) -> str: ...

    def operator_abort(self, source: str) -> str: ...

    def status(self) -> dict[str, object]:
        """A JSON-able snapshot for ``fresco-bridge ctl status``."""
        ...

    # -- the core the kinds share (the daemon, the kinds' groups, telemetry) -----------------
    def add_listener(self, listener: StepListener | EventListener) -> None: ...

    def event(self, kind: str, reason: str, **extra: object) -> None: ...

    def enter_hold(self, reason: str) -> None: ...

    def resume_from(self, session: int, step: int, time: float) -> None:
        """A resumed run: the next session is ``session + 1``, after committed ``step``."""
        ...

    def status_now(self) -> SiteStatus: ...

    def monitor_warning(self, reason: str, step: int) -> None: ...

    def correction_sample(self) -> CorrectionSample | None:
        """The displacement correction of the step just committed (None: the site has no
        ``[sites.correction]``, or that step's trial was not corrected); telemetry's."""
        ...
