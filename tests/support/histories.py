"""Seeded displacement/force histories for the updating tests (pure numpy + sim_actuator)."""

from __future__ import annotations

import numpy as np

from sim_actuator.models import make_model

DAMPER_BWBN = {
    "k0": 8.0, "fy": 12.0, "alpha": 0.05, "n": 1.0, "beta": 0.5, "gamma": 0.5, "A0": 1.0,
    "delta_a": 0.0, "delta_nu": 0.002, "delta_eta": 0.002, "zeta_s": 0.3, "p": 0.05, "q": 0.1,
    "psi0": 0.2, "delta_psi": 0.005, "lam": 0.5,
}  # fmt: skip
"""The rig's damper-bwbn specimen (sim_actuator preset), kN and mm."""


def disp_history(n: int, seed: int, amp: float = 4.0, dt: float = 0.01) -> np.ndarray:
    """An earthquake-like displacement history (mm): random sines under a rise-decay envelope."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    d = np.zeros(n)
    for _ in range(5):
        d += rng.uniform(0.3, 1.0) * np.sin(2 * np.pi * rng.uniform(0.3, 2.0) * t
                                            + rng.uniform(0, 2 * np.pi))
    env = np.minimum(1.0, t / (0.3 * t[-1])) * np.exp(-(((t - 0.5 * t[-1]) / (0.6 * t[-1])) ** 2))
    d *= env
    return amp * d / np.max(np.abs(d))


def ramped_sines(n: int, amplitude: float, seed: int) -> np.ndarray:
    """Two sines (seeded phase) under a 2 s linear ramp, 0.01 s samples (mm)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    phase = rng.uniform(0.0, 6.0)
    ramp = np.minimum(1.0, t / 2.0)
    return np.asarray(amplitude * ramp * (np.sin(2.3 * t) + 0.4 * np.sin(5.1 * t + phase)))


def force_history(d: np.ndarray, kind: str = "bwbn", params: dict[str, float] | None = None
                  ) -> np.ndarray:
    """Force (kN) of a sim_actuator law driven through ``d`` from the virgin state."""
    law = make_model(kind, **(DAMPER_BWBN if params is None else params))
    out = np.empty(len(d))
    for i, di in enumerate(d):
        out[i] = law.set_trial(float(di))[0]
        law.commit()
    return out
