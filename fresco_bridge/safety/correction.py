"""The outer-loop displacement correction per control point, as a pure verdict.

Reaction-frame compliance, a pin gap or servo undershoot leave the specimen short of the
command: the controller reports the target reached, but an external transducer behind the
compliance says otherwise. Labs close that gap by iterating the command (UIUC's LBCB plugin:
"elastic deformation correction", its ``StepTolerances``). Here, per control point ``i`` with
target ``t``, last command ``c`` and measured ``m``:

* every corrected point within ``tolerance`` (``|t - m| <= tol``): **converged**;
* else, after ``max_iterations`` corrections: **not converged** → the policy;
* else the next command ``c + gain * (t - m)`` (``gain`` <= 1: behind a series compliance or a
  pin gap the specimen then approaches the target from one side and never passes it, so an
  inelastic specimen sees no excursion the integrator did not ask for);
  if that lies farther than ``max_correction``
  from the target on any point: **beyond max_correction** → the policy, and it is never
  proposed (so never forwarded);
* a measurement that is not finite: **HOLD**, whatever the policy.

The policy (``hold``, default, or ``accept-with-event``) decides what a terminal verdict that is
not convergence does: HOLD the site, or answer the integrator with the last measurement and
record an event. A proposed command is only a proposal: the caller sends it through the same
ctrl limits and state table as any command (``sites/correction_loop.py``), so a correction can
never bypass a limit. Pure logic: no I/O, no clock; the converged check allocates nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

CorrectionPolicy = Literal["hold", "accept-with-event"]
Outcome = Literal["converged", "beyond-max-correction", "not-converged", "non-finite", "refused"]


@dataclass(frozen=True, slots=True)
class CorrectionSettings:
    """The correction of one site, one entry per control point (mm); a point with tolerance
    ``inf`` is not corrected (its command stays the target)."""

    tolerance: tuple[float, ...]
    max_correction: tuple[float, ...]
    max_iterations: int = 5
    gain: float = 1.0
    policy: CorrectionPolicy = "hold"

    def __post_init__(self) -> None:
        n = len(self.tolerance)
        if n == 0 or len(self.max_correction) != n:
            raise ValueError(f"correction: {n} tolerance(s) and {len(self.max_correction)} "
                             "max_correction(s); one of each per control point")
        for i, (tol, most) in enumerate(zip(self.tolerance, self.max_correction, strict=True)):
            if not (tol > 0.0 and most >= 0.0) or math.isnan(most):
                raise ValueError(f"correction of control point {i + 1}: tolerance {tol!r} mm "
                                 f"must be > 0 and max_correction {most!r} mm >= 0")
        if self.max_iterations < 1:
            raise ValueError(f"correction: max_iterations {self.max_iterations} must be >= 1")
        if not 0.0 < self.gain <= 1.0:
            raise ValueError(f"correction: gain {self.gain!r} must be in (0, 1]: above 1 a "
                             "correction overshoots the target, and an inelastic specimen "
                             "keeps the excursion in its history")

    @property
    def n(self) -> int:
        return len(self.tolerance)


@dataclass(frozen=True, slots=True)
class Terminal:
    """How a step's correction ended. ``hold``: the site must HOLD; otherwise the step is
    answered with the last measurement (``event``: the correction did not succeed and that is
    recorded)."""

    outcome: Outcome
    hold: bool
    point: int = -1
    """The first control point (0-based) that decided it; -1 for convergence."""
    value: float = math.nan
    """Its residual |target - measured| (or the proposed offset from the target), mm."""
    bound: float = math.nan
    """The bound it was checked against (tolerance or max_correction), mm."""

    @property
    def event(self) -> bool:
        return self.outcome != "converged"

    def describe(self) -> str:
        where = f"control point {self.point + 1}"
        if self.outcome == "converged":
            return "converged"
        if self.outcome == "refused":
            return "a command was not forwarded (a limit, the site's state or the controller)"
        if self.outcome == "non-finite":
            return f"{where}: measured displacement {self.value!r} mm is not finite"
        if self.outcome == "beyond-max-correction":
            return (f"{where}: the next corrected command would be {self.value:.6g} mm from the "
                    f"target, beyond max_correction {self.bound:g} mm; not sent")
        return (f"{where}: residual {self.value:.6g} mm still above the tolerance "
                f"{self.bound:g} mm after the last allowed correction")


CONVERGED = Terminal("converged", hold=False)
REFUSED = Terminal("refused", hold=True)
"""The command path forwarded nothing: it has already put the site in HOLD (or it was not
running); the correction ends there."""


def needs_warning(settings: CorrectionSettings, corrections: int) -> bool:
    """A step that needed more than half of ``max_iterations`` corrections: worth a warning
    (the rig drifts, or the gain is too low) before steps start failing."""
    return 2 * corrections > settings.max_iterations


def correct(
    settings: CorrectionSettings,
    target: tuple[float, ...],
    command: tuple[float, ...],
    measured: tuple[float, ...],
    corrections: int,
) -> tuple[float, ...] | Terminal:
    """The next command, or how the step's correction ends.

    ``command`` is the command the controller last reached (after limits: maybe clamped),
    ``measured`` what the chosen channel reads there, ``corrections`` how many corrected
    commands this step has sent already (0 after the target itself).
    """
    tolerance = settings.tolerance
    worst = -1
    for i in range(settings.n):
        tol = tolerance[i]
        if tol == math.inf:
            continue
        m = measured[i]
        if not math.isfinite(m):
            return Terminal("non-finite", hold=True, point=i, value=m)
        if worst < 0 and abs(target[i] - m) > tol:
            worst = i
    if worst < 0:
        return CONVERGED
    hold = settings.policy == "hold"
    if corrections >= settings.max_iterations:
        return Terminal("not-converged", hold=hold, point=worst,
                        value=abs(target[worst] - measured[worst]), bound=tolerance[worst])
    gain, most = settings.gain, settings.max_correction
    proposed = list(command)
    for i in range(settings.n):
        if tolerance[i] == math.inf:
            proposed[i] = target[i]
            continue
        c = command[i] + gain * (target[i] - measured[i])
        off = abs(c - target[i])
        if not off <= most[i]:
            return Terminal("beyond-max-correction", hold=hold, point=i, value=off,
                            bound=most[i])
        proposed[i] = c
    return tuple(proposed)


def residual(settings: CorrectionSettings, target: tuple[float, ...],
             measured: tuple[float, ...]) -> float:
    """The largest |target - measured| over the corrected control points, mm."""
    return max((abs(t - m) for t, m, tol in zip(target, measured, settings.tolerance,
                                                 strict=True) if tol != math.inf), default=0.0)
