"""The source paper's case-study constants and the study's own choices (mm, kN, s).

Paper (section 3.2): two-story frame, 20222.8 kg per floor, Rayleigh 5 % in modes 1-2,
explicit Newmark at dt = 0.01 s, record scaled to a PGA of 300 cm/s^2, an offline database of
2500 samples of the tested damper from a conventional run. The assumed Bilinear of Table 1 is
the updaters' (``updating.registry.PAPER_BILINEAR``: their default law and start). The frame
itself (stiffness, damper sizing) is the demo's (``fresco_bridge.integrator.demo``), whose
docstring says why.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Literal

CASES: Final = (
    "reference",
    "conventional_paper",
    "conventional_calibrated",
    "offline_ann",
    "online_ukf",
    "online_ann",
    "online_improved",
)
"""Every case of the study, in the paper's order (Table 2) plus ours."""

INTEGRATORS: Final = ("builtin", "opensees")
"""What integrates the frame: the in-process explicit Newmark, or OpenSeesPy against a bridge."""

LAYOUTS: Final = ("paper", "generalisation")
"""paper: twin in story 1 beside the tested damper; generalisation: twin in story 2."""

PAPER_PGA_M_S2: Final = 3.0
"""300 cm/s^2."""

OFFLINE_SAMPLES: Final = 2500
"""Size of the offline database (the paper's); a shorter conventional run gives all its steps."""

SYNTHETIC_DURATION_S: Final = 20.0
"""Length of the seeded Kanai-Tajimi record used when no record file is given."""

SPECIMEN_PRESET: Final = "damper-bwbn"
"""sim_actuator preset whose specimen is the tested damper by default (degrading, pinching)."""

MENEGOTTO_PINTO_DAMPER: Final[dict[str, float]] = {
    "k0": 8.0, "fy": 12.0, "alpha": 0.03, "R0": 12.0, "cR1": 0.925, "cR2": 0.15,
    "a1": 0.03, "a2": 1.0, "a3": 0.03, "a4": 1.0,
}  # fmt: skip
"""The out-of-family specimen (``--specimen menegotto-pinto``): sized like the BWBN damper
(k0 8 kN/mm, fy 12 kN), Steel02 transitions (R0 12, the recommended cR1/cR2) and 3 % isotropic
hardening per yield excursion unit; illustrative, not calibrated to a test."""

IN_FAMILY_SPECIMENS: Final[dict[str, tuple[str, dict[str, float]]]] = {
    "bilinear": ("bilinear", {"k0": 8.0, "fy": 12.0, "alpha": 0.05}),
    "bouc-wen": ("bouc-wen", {"k0": 8.0, "fy": 12.0, "alpha": 0.05, "n": 1.0, "beta": 0.5,
                              "gamma": 0.5, "A": 1.0}),
}  # fmt: skip
"""The in-family specimens (``--specimen bilinear``, ``--specimen bouc-wen``): laws the updaters
can represent (the calibrated Bilinear, ``online_ukf``'s Bilinear; ``online_improved``'s Baber-Wen
law with its degradation off), sized like the BWBN damper's backbone (k0 8 kN/mm, fy 12 kN,
alpha 0.05; the Bouc-Wen one is the BWBN damper without pinching or degradation). On them an
updater can only lose against a good offline calibration: they test that it does no harm."""

OUT_OF_FAMILY_SPECIMENS: Final = ("bwbn", "menegotto-pinto")
"""Specimens outside every updater's family: where updating has to earn its keep."""

SPECIMENS: Final = (*OUT_OF_FAMILY_SPECIMENS, *IN_FAMILY_SPECIMENS)


@dataclass(frozen=True)
class TargetSpec:
    """One restated updating target, scored per causality over the runs it applies to.

    Every target is about ``TARGET_SUBJECT`` in ``TARGET_LAYOUT``. ``kind``: ``reduction``
    (each of ``reductions``, (metric, minimum % below ``TARGET_BASELINE``), on every run; with
    ``median_pct``, also the median over the runs of the first metric's reduction), ``below``
    (MAETH below the case ``rival`` on every run where it ran), ``no-harm`` (MAETH at most
    ``max_ratio`` × ``TARGET_BASELINE``'s on every run) or ``bounded`` (see
    ``BOUNDED_PEAK_RATIO``). ``specimen``: one, several, or None (every specimen);
    ``noise_pct`` None: every noise level.
    """

    name: str
    kind: Literal["reduction", "below", "no-harm", "bounded"]
    specimen: str | tuple[str, ...] | None = None
    noise_pct: float | None = None
    reductions: tuple[tuple[str, float], ...] = ()
    median_pct: float | None = None
    rival: str | None = None
    max_ratio: float | None = None


TARGET_SUBJECT: Final = "online_improved"
TARGET_BASELINE: Final = "conventional_calibrated"
TARGET_LAYOUT: Final = "generalisation"

BOUNDED_PEAK_RATIO: Final = 2.0
"""A run is *bounded* when the subject's metrics are finite and its peak |twin force| is at most
this multiple of the peak true force. Our choice: a twofold overshoot is far beyond any fitted
law's error, yet it flags a twin that has left the physics before its force diverges."""

TARGETS: Final[tuple[TargetSpec, ...]] = (
    TargetSpec("bwbn_noise0", "reduction", "bwbn", 0.0, (("maeth", 85.0), ("rmseth", 90.0))),
    TargetSpec("bwbn_noise1", "reduction", "bwbn", 1.0, (("maeth", 80.0),)),
    TargetSpec("menegotto_pinto", "reduction", "menegotto-pinto", None, (("maeth", 25.0),),
               median_pct=50.0),
    TargetSpec("below_online_ukf", "below", OUT_OF_FAMILY_SPECIMENS, rival="online_ukf"),
    TargetSpec("below_online_ann", "below", OUT_OF_FAMILY_SPECIMENS, rival="online_ann"),
    TargetSpec("in_family_no_harm", "no-harm", tuple(IN_FAMILY_SPECIMENS), max_ratio=1.1),
    TargetSpec("bounded", "bounded"),
)
"""The updating targets, restated (BENCHMARKS.md, "Online updating"): what ``study paper``'s
summary scores. A (specimen, noise) that no ``reduction`` or ``no-harm`` target covers has no
target. Out of family updating must beat the calibrated Bilinear by far; in family it must not
lose to it by more than a tenth (``no-harm``: an updater that ends worse than its offline start
did harm)."""
