"""Records without a command channel: which effects the diagnosis cannot see, and why.

Many lab records keep only the measured displacement (an LVDT or the actuator's own
transducer) and the force: the command the controller sent is lost. The diagnosis then drives
the baseline law by the *measured* displacement (``Record.no_command``). What that hides:

* **the interface layer** — every effect that acts between the command and the piston: a
  delay (``actuator_delay``), an amplitude error (``actuator_amplitude``), an end-point
  undershoot against the direction of motion (``actuator_undershoot``, OpenFresco's
  ``ErrorSimUndershoot``), a servo lag or friction in the actuator that makes the piston
  trail the command. Each one is a difference between command and piston; with the piston
  as the only displacement there is nothing to take the difference against. A lag between
  the displacement and the force channels would be a data-acquisition skew, not any of these,
  and fitting one would guess. They are reported as *not identifiable*, never fitted.
* **the displacement sensor's own errors** — an LVDT offset is defined against the command
  (``sensor_bias`` keeps its load-cell offset only), and LVDT noise drives the law instead of
  showing as a residual (``sensor_noise`` keeps its load-cell part only).

What stays identifiable, because it acts between the measured displacement and the measured
force: the specimen's law and its pinching or degradation, a pin gap *behind* the displacement
transducer (``backlash``: a force plateau around each reversal; a transducer on the specimen
side of the gap would hide it), Coulomb friction and viscosity on the measured velocity
(``friction``, ``rate_dependence``: a fixture in parallel with the specimen — a fixture that
cannot be told from the specimen's own rigid-plastic part, as with a command), the load cell's
offset and noise. The summary and the JSON (``not_identifiable``) name what was hidden.
"""

from __future__ import annotations

from collections.abc import Sequence

from .load import Record

__all__ = ["NOT_IDENTIFIABLE", "PARTLY_IDENTIFIABLE", "hidden_effects", "hidden_summary"]

NOT_IDENTIFIABLE: dict[str, str] = {
    "actuator_delay": "a delay of the piston behind the command: there is no command to lag "
                      "behind",
    "actuator_amplitude": "piston/command - 1: there is no command to compare the piston with",
    "actuator_undershoot": "the piston's error against the direction of motion: there is no "
                           "command to fall short of",
}
"""Candidates that act between the command and the piston (the interface layer)."""
PARTLY_IDENTIFIABLE: dict[str, str] = {
    "sensor_bias": "only the load-cell offset (an LVDT offset is defined against the command)",
    "sensor_noise": "only the load-cell noise (LVDT noise drives the law)",
}
"""Candidates that keep only their force-channel part."""


def hidden_effects(record: Record, effects: Sequence[str]) -> dict[str, str]:
    """The candidates of ``effects`` the record cannot identify, with the reason (none when
    the record has a command channel)."""
    if not record.no_command:
        return {}
    return {e: why for e, why in NOT_IDENTIFIABLE.items() if e in effects}


def hidden_summary(record: Record, effects: Sequence[str]) -> list[str]:
    """One line per hidden or reduced candidate, for the summary and the notes."""
    if not record.no_command:
        return []
    return [*(f"{e}: not identifiable ({why})" for e, why in
              hidden_effects(record, effects).items()),
            *(f"{e}: {why}" for e, why in PARTLY_IDENTIFIABLE.items() if e in effects)]
