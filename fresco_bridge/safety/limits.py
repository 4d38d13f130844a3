"""Ctrl and daq limits per control point, with OpenFresco semantics and an explicit policy.

OpenFresco puts ``-lim lower upper`` on each control-point signal and its controls disagree on
what to do past it (``ECMtsCsi`` clamps silently, ``ECLabVIEW`` asks the operator). Here every
control point (actuator DOF, after the setup) carries its limits as data and one policy:

* ``reject`` (default): nothing is forwarded, the site goes to HOLD;
* ``clamp``: the clamped command is forwarded and a limit event is recorded every time;
* ``pause``: nothing is forwarded until an operator resumes; the resumed command is checked
  again with its increment/velocity violation approved, its absolute limits still hard.

Checks, in order, on the command ``c`` of each control point against the last command sent
``p`` (the reference) and the step time ``dt``: absolute ``disp_min <= c <= disp_max``;
increment ``|c - p| <= disp_increment``; velocity ``|c - p| / dt <= velocity``. A velocity
violation within the other limits can be split into ``k <= max_substeps`` equal sub-commands
(OpenFresco's ``getNumSubSteps``), sent in order. Measured forces past ``force_min/force_max``
(daq limits) always HOLD. Pure logic: no I/O, no clock; the pass case allocates nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

Policy = Literal["reject", "clamp", "pause"]
LimitKind = Literal["absolute", "increment", "velocity", "force"]
Action = Literal["clamp", "substep", "reject", "pause"]

INF = math.inf
_SEVERITY: dict[Policy, int] = {"clamp": 0, "pause": 1, "reject": 2}


def all_finite(values: tuple[float, ...]) -> bool:
    """True when no value is NaN or infinite. The happy path is one C-level sum (a NaN or an
    infinity makes the sum non-finite); only a non-finite sum, which finite values can also
    reach by overflow, is checked value by value."""
    return math.isfinite(sum(values)) or all(math.isfinite(v) for v in values)


@dataclass(frozen=True, slots=True)
class ControlPointLimits:
    """Limits of one control point (``actuator`` is 0-based here, 1-based in config/messages)."""

    actuator: int
    disp_min: float = -INF
    disp_max: float = INF
    disp_increment: float = INF
    velocity: float = INF
    step_time: float | None = None
    policy: Policy = "reject"
    max_substeps: int = 0
    force_min: float = -INF
    force_max: float = INF

    @property
    def has_ctrl_limits(self) -> bool:
        return (self.disp_min > -INF or self.disp_max < INF or self.disp_increment < INF
                or self.velocity < INF)

    @property
    def has_daq_limits(self) -> bool:
        return self.force_min > -INF or self.force_max < INF


@dataclass(frozen=True, slots=True)
class LimitHit:
    """One limit exceeded by one control point: what, by how much, and the policy applied."""

    actuator: int
    limit: LimitKind
    value: float
    bound: float
    policy: Policy

    @property
    def signal(self) -> str:
        kind = "daq force" if self.limit == "force" else "ctrl disp"
        return f"{kind}[{self.actuator + 1}]"

    def describe(self) -> str:
        unit = {"absolute": "mm", "increment": "mm", "velocity": "mm/s", "force": "kN"}
        what = {"absolute": "command", "increment": "increment |ctrl - last sent|",
                "velocity": "velocity |ctrl - last sent| / dt", "force": "measured force"}
        u = unit[self.limit]
        if math.isnan(self.value):
            return (f"{self.signal}: velocity limit {self.bound:g} {u} cannot be checked: no "
                    "step time (trial time does not advance; set step_time)")
        side = "above" if self.value > self.bound else "below"
        if self.limit in ("increment", "velocity"):
            side = "above"
        return (f"{self.signal}: {what[self.limit]} {self.value:.6g} {u} is {side} the "
                f"{self.limit} limit {self.bound:g} {u}")

    def as_record(self) -> dict[str, object]:
        return {"signal": self.signal, "limit": self.limit, "value": self.value,
                "bound": self.bound, "policy": self.policy, "actuator": self.actuator + 1}


@dataclass(frozen=True, slots=True)
class Verdict:
    """What to do with a command that is not simply forwarded.

    ``commands`` are the ctrl vectors to send, in order (empty for ``reject``/``pause``);
    ``hits`` the limits exceeded (empty for a plain ``substep``).
    """

    action: Action
    commands: tuple[tuple[float, ...], ...]
    hits: tuple[LimitHit, ...]

    def describe(self) -> str:
        return "; ".join(h.describe() for h in self.hits)


class Limiter:
    """The limits of one site's control points, checked on every command and measurement."""

    __slots__ = ("by_actuator", "has_ctrl", "has_daq", "n", "needs_reference")

    def __init__(self, limits: list[ControlPointLimits], n_actuators: int) -> None:
        table: list[ControlPointLimits | None] = [None] * n_actuators
        for lim in limits:
            if not 0 <= lim.actuator < n_actuators:
                raise ValueError(f"limits for actuator {lim.actuator + 1}: the setup has "
                                 f"{n_actuators} actuator(s)")
            if table[lim.actuator] is not None:
                raise ValueError(f"two limit entries for actuator {lim.actuator + 1}")
            table[lim.actuator] = lim
        self.by_actuator = tuple(table)
        self.n = n_actuators
        self.has_ctrl = any(lim is not None and lim.has_ctrl_limits for lim in table)
        self.has_daq = any(lim is not None and lim.has_daq_limits for lim in table)
        self.needs_reference = any(
            lim is not None and (lim.disp_increment < INF or lim.velocity < INF) for lim in table)

    def check_ctrl(
        self,
        ctrl: tuple[float, ...],
        reference: tuple[float, ...] | None,
        dt: float,
        *,
        approved: bool = False,
    ) -> Verdict | None:
        """``None`` when ``ctrl`` may be forwarded as is; otherwise what to do instead.

        ``reference`` is the last command sent (``None``: unknown, so no increment/velocity
        check); ``dt`` the trial time since the last commit (<= 0: unknown). ``approved``: an
        operator resumed a ``pause`` — its increment/velocity violations are waived, an
        absolute violation rejects.
        """
        hits: list[LimitHit] | None = None
        target: list[float] | None = None
        substeps = 1
        for i, lim in enumerate(self.by_actuator):
            if lim is None:
                continue
            c = ctrl[i]
            policy = lim.policy
            # absolute
            bound = lim.disp_max if c > lim.disp_max else lim.disp_min if c < lim.disp_min \
                else None
            if bound is not None:
                hits = hits if hits is not None else []
                abs_policy: Policy = "reject" if approved and policy == "pause" else policy
                hits.append(LimitHit(i, "absolute", c, bound, abs_policy))
                if policy == "clamp":
                    target = target if target is not None else list(ctrl)
                    c = target[i] = bound
            if reference is None:
                continue
            p = reference[i]
            d = c - p
            waived = approved and policy == "pause"
            # increment
            if abs(d) > lim.disp_increment and not waived:
                hits = hits if hits is not None else []
                hits.append(LimitHit(i, "increment", abs(d), lim.disp_increment, policy))
                if policy == "clamp":
                    target = target if target is not None else list(ctrl)
                    d = math.copysign(lim.disp_increment, d)
                    c = target[i] = p + d
            # velocity
            if lim.velocity == INF:
                continue
            step = lim.step_time if lim.step_time is not None else dt
            if not step > 0.0:
                if d != 0.0 and not waived:  # unknown dt: nothing to clamp to, so no clamp
                    hits = hits if hits is not None else []
                    hits.append(LimitHit(i, "velocity", math.nan, lim.velocity,
                                         "reject" if policy == "clamp" else policy))
                continue
            reach = lim.velocity * step
            if abs(d) <= reach:
                continue
            k = math.ceil(abs(d) / reach)
            if 2 <= k <= lim.max_substeps:
                substeps = max(substeps, k)
            elif not waived:
                hits = hits if hits is not None else []
                hits.append(LimitHit(i, "velocity", abs(d) / step, lim.velocity, policy))
                if policy == "clamp":
                    target = target if target is not None else list(ctrl)
                    c = target[i] = p + math.copysign(reach, d)
        if hits is None and substeps == 1:
            return None
        if hits:
            worst = max((h.policy for h in hits), key=_SEVERITY.__getitem__)
            if worst != "clamp":
                return Verdict(worst, (), tuple(hits))
        final = tuple(target) if target is not None else ctrl
        commands = (final,) if substeps == 1 or reference is None else \
            split(reference, final, substeps)
        if hits:
            return Verdict("clamp", commands, tuple(hits))
        return Verdict("substep", commands, ())

    def check_daq(self, force: tuple[float, ...]) -> LimitHit | None:
        """The first measured force past its daq limit (policy always ``reject`` → HOLD)."""
        for i, lim in enumerate(self.by_actuator):
            if lim is None:
                continue
            f = force[i]
            if f > lim.force_max:
                return LimitHit(i, "force", f, lim.force_max, "reject")
            if f < lim.force_min:
                return LimitHit(i, "force", f, lim.force_min, "reject")
        return None


def split(
    start: tuple[float, ...], end: tuple[float, ...], k: int
) -> tuple[tuple[float, ...], ...]:
    """``k`` equal sub-commands from ``start`` (excluded) to ``end`` (included, exactly)."""
    subs = [
        tuple(s + (e - s) * j / k for s, e in zip(start, end, strict=True)) for j in range(1, k)
    ]
    subs.append(end)
    return tuple(subs)
