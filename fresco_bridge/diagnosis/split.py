"""The split: the calibration part every fit sees, the withheld part every score is on.

The calibration part is the first samples that carry ``Options.calibration_fraction`` of the
command's signal energy (sum of (c − mean c)²), the rest is withheld, so a quiet tail never
becomes the whole withheld part (on a stationary record: the first ~60 % of the samples). The
command is the test's input, known before any measurement: the split never depends on a
measured (possibly withheld) value. Pure: no fitting.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .load import DiagnosisInputError, Record
from .options import Options

__all__ = ["MIN_CALIBRATION", "MIN_WITHHELD", "Split", "split", "stop_of"]

MIN_CALIBRATION = 60
MIN_WITHHELD = 40
"""The shortest parts worth fitting on and scoring on (samples)."""


@dataclass(frozen=True)
class Split:
    """Samples ``[0, stop)`` calibrate, ``[stop, n)`` are withheld; ``note`` says so."""

    stop: int
    samples: int
    note: str

    @property
    def withheld(self) -> slice:
        return slice(self.stop, self.samples)

    @property
    def calibration(self) -> slice:
        return slice(0, self.stop)


def split(record: Record, opts: Options) -> Split:
    """The record's split; DiagnosisInputError when a part would be too short to use."""
    n = record.size
    stop = stop_of(record, opts)
    if stop < MIN_CALIBRATION or n - stop < MIN_WITHHELD:
        raise DiagnosisInputError(
            f"{record.source}: record too short to split: {n} samples give {stop} to calibrate "
            f"and {n - stop} to withhold (need >= {MIN_CALIBRATION} and >= {MIN_WITHHELD})")
    what = "measured displacement's" if record.no_command else "command's"
    return Split(stop, n, f"split by the {what} energy: calibration samples 0-{stop} "
                          f"({100.0 * stop / n:.0f} % of the samples, "
                          f"{100.0 * opts.calibration_fraction:.0f} % of the energy)")


def stop_of(record: Record, opts: Options) -> int:
    """The calibration part's length: the first samples that carry ``calibration_fraction`` of
    the command's signal energy, sum of (c − mean c)² (the time fraction for a constant
    command). The command only: it is the test's input, so the split never depends on a
    measured (possibly withheld) value."""
    c = record.cmd - float(np.mean(record.cmd))
    energy = np.cumsum(c * c)
    if not energy.size or energy[-1] <= 0.0:
        return round(opts.calibration_fraction * record.size)
    return int(np.searchsorted(energy, opts.calibration_fraction * energy[-1])) + 1
