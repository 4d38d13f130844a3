"""Step 1 of the learned reversal-state law (``fresco_bridge.updating.reversal_state``; issue 9,
BENCHMARKS.md "updating part 10"): its capacity in hindsight on the design records.

For each (specimen, record seed): the reference case (``kanai_tajimi`` 3 m/s², 20 s, 0 % noise,
generalisation layout) gives the tested element's whole history (d, F) and the twin's; the
design runs' offline database is the first ``OFFLINE_SAMPLES`` of the conventional paper-layout
run of the same record (``updater_design``). The law is fitted (an ensemble of ``members``
networks from seeded starts, ``iterations`` LM iterations each) to ``train`` — any of
``tested``, ``offline``, ``twin`` joined by ``+`` (``twin``: the twin's own true history, the
upper bound on capacity, not available online; ``tested@K``, ``twin@K``: those of record seed
K, a data-coverage diagnostic) — then the twin free-runs in closed loop with
it (``FixedModelUpdater``). Printed per run: the fit's rms (teacher-forced, on the training
histories), the teacher-forced and free-run rms along the twin's history, the twin's MAETH, its
largest error before and after step ``EARLY`` (where the errors sit), the peak |twin force|
(does the recurrence stay bounded), the calibrated Bilinear's MAETH and the 0 % target (10 %
of it).

``taskset -c 0 python -m benchmarks.reversal_state [--specimen menegotto-pinto] [--seed 1]
[--train tested+offline] [--hidden 16,16] [--members 5] [--variables absolute] [--drop energy]``
(~10 s per run on one core).

Online (a probe run although step 1 failed; BENCHMARKS.md part 10), ``benchmarks.updater_design
--factory`` functions: ``online`` (``ReversalStateUpdater`` alone) and ``mixture`` (design H, the
default ``online_improved``, with it as a sixth expert scored like the others; options go to
the law): ``taskset -c 0 python -m benchmarks.updater_design --workers 1 --factory
benchmarks.reversal_state:mixture --baseline``.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np
import numpy.typing as npt

from fresco_bridge import indicators
from fresco_bridge.integrator import kanai_tajimi
from fresco_bridge.study.calibrate import calibrate_bilinear
from fresco_bridge.study.constants import OFFLINE_SAMPLES, PAPER_BILINEAR
from fresco_bridge.study.simulate import simulate_case, specimen_model
from fresco_bridge.updating import reversal_state as rs
from fresco_bridge.updating.improved import OnlineImproved
from fresco_bridge.updating.lm import LmOptions
from fresco_bridge.updating.mlp import Mlp
from fresco_bridge.updating.refit import law_forces
from fresco_bridge.updating.updaters import FixedModelUpdater
from sim_actuator.models import make_model

FloatArray = npt.NDArray[np.float64]

EARLY = 750
"""Steps counted as the early part of a record (first yield and the first cycles)."""


def fit_ensemble(histories: list[tuple[FloatArray, FloatArray, float]], sc: rs.Scales,
                 hidden: tuple[int, ...], members: int, iterations: int
                 ) -> tuple[Mlp, FloatArray, float]:  # fmt: skip
    """(net, thetas members × n, mean fit rms) of ``members`` fits from seeds 0, 1, …"""
    net = Mlp((len(sc.names), *hidden, 1))
    thetas, rms = [], []
    for seed in range(members):
        theta, r = rs.fit_law(net, net.init_params(np.random.default_rng(seed)), histories, sc,
                              LmOptions(max_iterations=iterations, mu=1e-3))  # fmt: skip
        thetas.append(theta)
        rms.append(r)
    return net, np.array(thetas), float(np.mean(rms))


def online(disp: FloatArray, force: FloatArray, **options: Any) -> rs.ReversalStateUpdater:
    """The learned law alone, refitted online."""
    return rs.ReversalStateUpdater(offline=(disp, force), **options)


def mixture(disp: FloatArray, force: FloatArray, **options: Any) -> OnlineImproved:
    """Design H with the learned law as a sixth expert."""
    from benchmarks.refit_families import _with_expert

    return _with_expert(OnlineImproved(offline=(disp, force)), "reversal-state",
                        online(disp, force, **options))


def _other(specimen: str, token: str) -> tuple[FloatArray, FloatArray]:
    """``tested@K`` / ``twin@K``: that element's history in the reference case of record seed
    K (a data-coverage diagnostic: more elements' histories than an online law ever sees)."""
    name, _, seed = token.partition("@")
    ref = simulate_case("generalisation", specimen,
                        FixedModelUpdater("reference", specimen_model(specimen)),
                        kanai_tajimi(3.0, 20.0, seed=int(seed)))  # fmt: skip
    return ((ref.tested_drift, ref.tested_force) if name == "tested" else
            (ref.twin_drift, ref.twin_true_force))


def capacity(specimen: str, seed: int, train: str = "tested+offline",
             hidden: tuple[int, ...] = (16, 16), members: int = 5, iterations: int = 100,
             variables: str = "absolute", drop: tuple[str, ...] = ()) -> dict[str, Any]:
    """One run of step 1 (module docstring)."""
    motion = kanai_tajimi(3.0, 20.0, seed=seed)
    ref = simulate_case("generalisation", specimen,
                        FixedModelUpdater("reference", specimen_model(specimen)), motion)
    conv = simulate_case("paper", specimen,
                         FixedModelUpdater("conventional_paper",
                                           make_model("bilinear", **PAPER_BILINEAR)), motion)
    off_d = conv.tested_drift[:OFFLINE_SAMPLES].copy()
    off_f = conv.tested_force[:OFFLINE_SAMPLES].copy()
    calibrated = FixedModelUpdater("conventional_calibrated",
                                   make_model("bilinear", **calibrate_bilinear(off_d, off_f)))
    base = simulate_case("generalisation", specimen, calibrated, motion)
    conv_cal = indicators.maeth(base.twin_true_force, base.twin_force)
    pool = {"tested": (ref.tested_drift, ref.tested_force), "offline": (off_d, off_f),
            "twin": (ref.twin_drift, ref.twin_true_force)}
    histories = [(*(pool[name] if "@" not in name else _other(specimen, name)), 1.0)
                 for name in train.split("+")]
    sc = rs.scales(histories[0][0], histories[0][1], variables, drop)
    start = time.process_time()
    net, thetas, fit_rms = fit_ensemble(histories, sc, hidden, members, iterations)
    fit_s = time.process_time() - start
    law = rs.ReversalStateLaw(net, thetas, sc)
    x, y, w = rs.features(ref.twin_drift, ref.twin_true_force, sc)
    g = np.array([law.params.g(net, z)[0] for z in x])
    twin_teacher = float(np.sqrt(np.mean(w * (g - y) ** 2))) * sc.force
    own = law_forces(law.clone(), ref.twin_drift)
    twin_open = float(np.sqrt(np.mean((own - ref.twin_true_force) ** 2)))
    run = simulate_case("generalisation", specimen, FixedModelUpdater("reversal-state", law),
                        motion)
    err = np.abs(run.twin_true_force - run.twin_force)
    return {"specimen": specimen, "seed": seed, "train": train, "hidden": hidden,
            "members": members, "variables": variables, "drop": drop, "fit_rms": fit_rms,
            "twin_teacher_rms": twin_teacher, "twin_open_rms": twin_open,
            "maeth": float(np.max(err)), "early_max": float(np.max(err[:EARLY])),
            "late_max": float(np.max(err[EARLY:])),
            "peak_twin_force": float(np.max(np.abs(run.twin_force))),
            "conv_cal": conv_cal, "target": 0.1 * conv_cal, "fit_cpu_s": fit_s}  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--specimen", action="append",
                        choices=("bwbn", "menegotto-pinto"))
    parser.add_argument("--seed", type=int, action="append")
    parser.add_argument("--train", default="tested+offline")
    parser.add_argument("--hidden", default="16,16")
    parser.add_argument("--members", type=int, default=5)
    parser.add_argument("--iterations", type=int, default=100)
    parser.add_argument("--variables", default="absolute", choices=tuple(rs.VARIABLES))
    parser.add_argument("--drop", action="append", default=[])
    args = parser.parse_args(argv)
    hidden = tuple(int(h) for h in args.hidden.split(","))
    print("| specimen | seed | train | net | variables | fit rms | twin teacher rms | twin "
          "free rms | twin MAETH | early max | late max | peak |F twin| | conv_cal | target |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for specimen in args.specimen or ["menegotto-pinto", "bwbn"]:
        for seed in args.seed or [1, 2]:
            r = capacity(specimen, seed, args.train, hidden, args.members, args.iterations,
                         args.variables, tuple(args.drop))
            less = f" − {', '.join(r['drop'])}" if r["drop"] else ""
            print(f"| {specimen} | {seed} | {r['train']} | {args.hidden}×{args.members} | "
                  f"{r['variables']}{less} | {r['fit_rms']:.3f} | {r['twin_teacher_rms']:.3f} | "
                  f"{r['twin_open_rms']:.3f} | {r['maeth']:.3f} | {r['early_max']:.3f} | "
                  f"{r['late_max']:.3f} | {r['peak_twin_force']:.1f} | {r['conv_cal']:.3f} | "
                  f"{r['target']:.3f} |", flush=True)


if __name__ == "__main__":
    main()
