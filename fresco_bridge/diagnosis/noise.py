"""How much of a gap is sensor noise: the white part every record has, and the random part
that coloured noise adds.

The white part (``indicators.white_noise_std``: the MAD of the first differences) is what the
verdict removes from every withheld gap before effects compete: no effect predicts it. Noise
on a real load cell or LVDT is often low-passed by its conditioning, and the white estimate
sees only part of it; the rest looks like a systematic gap that no candidate explains. What
tells it from a misfit is that it has nothing to do with the loop: a law that misses the
specimen, or an interface error, leaves a residual that the loop's state (displacement,
velocity, direction, force) predicts in part. When the state explains less than
:data:`RANDOM_SHARE` of a channel's calibration residual, and the residual is no smoother than
conditioning noise can be (:data:`MAX_COLOUR_RATIO`), the ``sensor_noise`` candidate claims
that residual's whole unexplained std on the channel instead of its white part.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .. import indicators as ind
from .load import Record

__all__ = ["MAX_COLOUR_RATIO", "RANDOM_SHARE", "NoiseEstimate", "estimate_noise", "loop_state"]

FloatArray = npt.NDArray[np.float64]

RANDOM_SHARE = 0.1
"""Largest share of a calibration residual's variance the loop's state may explain for the
residual to count as noise (``docs/diagnosis.md``)."""
MAX_COLOUR_RATIO = 4.0
"""Largest ratio of the claimed std to the white std. First-order noise with corner f_c,
sampled every dt, shows a white std of about sqrt(2π f_c dt) of its own: a ratio of 4 is a
corner at 1 % of the sampling rate. A smoother residual is not conditioning noise but the
test's own motion band: a friction damper's 36 % misfit on a 2 Hz sine, which the linear state
basis explains only 6 % of, had a ratio of 19."""


@dataclass(frozen=True, slots=True)
class NoiseEstimate:
    """Per channel (force kN, displacement mm): the white std, and the std the
    ``sensor_noise`` candidate claims (the white one, or the random part when larger)."""

    white_force: float
    white_disp: float
    claim_force: float
    claim_disp: float

    @property
    def white(self) -> tuple[float, float]:
        return self.white_force, self.white_disp

    @property
    def claim(self) -> tuple[float, float]:
        return self.claim_force, self.claim_disp


def loop_state(cmd: FloatArray, force: FloatArray) -> FloatArray:
    """Columns of the loop's state at each sample: offset, displacement, velocity, direction,
    force, and the products that shape a hysteresis loop (d·|d|, v·|v|, direction·|d|,
    direction·force)."""
    v = np.gradient(cmd)
    s = np.sign(v)
    return np.column_stack([np.ones_like(cmd), cmd, v, s, force, cmd * np.abs(cmd),
                            v * np.abs(v), s * np.abs(cmd), s * force])


def _claim(residual: FloatArray, state: FloatArray, white: float) -> float:
    fitted = ind.state_unexplained(residual, state)
    if fitted is None or fitted[0] >= RANDOM_SHARE:
        return white
    rest = float(np.std(fitted[1]))
    return rest if white < rest <= MAX_COLOUR_RATIO * white else white


def estimate_noise(record: Record, force: FloatArray, disp: FloatArray | None,
                   stop: int) -> NoiseEstimate:
    """The noise of ``record`` from the baseline's prediction (``force``, ``disp``) on the
    calibration part (samples before ``stop``) only."""
    r_f = (record.force - force)[:stop]
    state = loop_state(record.cmd[:stop], force[:stop])
    white_f = ind.white_noise_std(r_f)
    white_d = claim_d = 0.0
    if record.meas_disp is not None and disp is not None:
        r_d = (record.meas_disp - disp)[:stop]
        white_d = ind.white_noise_std(r_d)
        claim_d = _claim(r_d, state, white_d)
    return NoiseEstimate(white_f, white_d, _claim(r_f, state, white_f), claim_d)
