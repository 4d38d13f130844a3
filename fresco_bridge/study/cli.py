"""``fresco-bridge study paper``: parser and handler (registered by ``fresco_bridge.cli``).

It writes every run's tables and a summary, and ends its output with the verdicts on the
restated updating targets (BENCHMARKS.md, "Online updating")."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from fresco_bridge.study.constants import (
    CASES,
    INTEGRATORS,
    PAPER_PGA_M_S2,
    SPECIMENS,
    SYNTHETIC_DURATION_S,
)

__all__ = ["add_study_parser", "study_command"]


def _noise(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r} (a percentage, e.g. 1)") from None
    if not (math.isfinite(value) and 0.0 <= value <= 50.0):
        raise argparse.ArgumentTypeError(f"must be a percentage in [0, 50], got {text!r}")
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def add_study_parser(sub: Any) -> None:
    """``study paper`` and its options."""
    # Imported when the parser is built, not when `cli` is: the command line stays light to load.
    from fresco_bridge.integrator.coupling import CAUSALITIES
    from fresco_bridge.updating.cli import parse_option

    p_study = sub.add_parser("study", help="reproducible studies (the source paper's case study)")
    studies = p_study.add_subparsers(dest="study", required=True)
    p = studies.add_parser(
        "paper",
        help="online model updating: the paper's Table 3 in two layouts, every updater",
        description="The source paper's case study in process: the two-story frame, the tested "
                    "damper in story 1, its numerical twin beside it (paper layout) or in story 2 "
                    "(generalisation layout), every case from reference to online_improved. "
                    "Writes study.json, table.md and figures per run; prints the tables.",
    )  # fmt: skip
    p.add_argument("--record", type=Path, action="append", default=None, metavar="AT2",
                   help="ground motion (PEER .AT2 or text), scaled to PGA "
                        f"{PAPER_PGA_M_S2:g} m/s²; repeatable (default: a seeded synthetic "
                        f"record, {SYNTHETIC_DURATION_S:g} s, one per --seed)")  # fmt: skip
    p.add_argument("--specimen", choices=SPECIMENS, action="append", default=None,
                   help="tested damper law: bwbn (rig preset damper-bwbn, default) or "
                        "menegotto-pinto (outside every updater's family); bilinear or "
                        "bouc-wen (inside it: updating must do no harm); repeatable")
    p.add_argument("--noise", type=_noise, action="append", default=None, metavar="PCT",
                   help="load-cell noise, std in %% of the tested damper's peak force in a "
                        "noise-free reference run (default 0); repeatable")
    p.add_argument("--seed", type=int, action="append", default=None,
                   help="noise, synthetic record and updater seed (default 1); repeatable")
    p.add_argument("--causality", choices=CAUSALITIES, action="append", default=None,
                   help="what the twin's step i may learn from: same-step (the tested damper's "
                        "step i, the paper's order, default) or previous-step (only through "
                        "step i-1, what a twin served live under OpenSees can honour); "
                        "repeatable; recorded in study.json")
    p.add_argument("--integrator", choices=INTEGRATORS, default="builtin",
                   help="builtin (the in-process explicit Newmark, default) or opensees "
                        "(OpenSeesPy integrates the same frame; both dampers are genericClient "
                        "elements served by a bridge started for each case: the tested one by "
                        "a sim site with the true law and the run's load-cell noise, the twin "
                        "by an updatable site); recorded in study.json")
    p.add_argument("--cases", default=None,
                   help=f"comma-separated subset of {','.join(CASES)} (default: all available)")
    p.add_argument("--steps", type=_positive_int, default=None,
                   help="stop after this many steps (default: the whole record)")
    p.add_argument("--ann-iterations", type=_positive_int, default=None, metavar="N",
                   help="cap online_ann's LM at N iterations per step (default 8, equal in "
                        "accuracy to the paper's 50: BENCHMARKS.md, 'Online updating'; "
                        "recorded in study.json)")
    p.add_argument("--ann-option", type=parse_option, action="append", default=[],
                   metavar="KEY=VALUE",
                   help="an online_ann option (JSON value), repeatable, e.g. rtol=0.01 (a "
                        "relative-decrease stop) or single_precision_hessian=false "
                        "(with --ann-iterations 50: the paper's exact fit); recorded in "
                        "study.json")
    p.add_argument("--pretrain-iterations", type=_positive_int, default=1000, metavar="N",
                   help="LM iterations of the ANN's offline pre-training (default 1000)")
    p.add_argument("--workers", type=_positive_int, default=None,
                   help="local worker processes (default: one per core; 1 = in this process)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the cases on this Dask scheduler (tcp://host:8786)")
    p.add_argument("-o", "--out", type=Path, default=Path("study-paper"),
                   help="output directory (default ./study-paper)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG figures")


def study_command(args: argparse.Namespace) -> int:
    """Run the study; bad input -> one line on stderr and exit 2."""
    from fresco_bridge.study.paper import StudyError

    try:
        return _run(args)
    except StudyError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


_ANN_RESERVED = ("model", "model_file", "offline", "seed", "pretrain_iterations", "max_iterations")
"""online_ann options the study sets itself (--seed, --pretrain-iterations, --ann-iterations)."""


def _ann_options(pairs: list[tuple[str, Any]]) -> tuple[tuple[str, Any], ...]:
    """--ann-option pairs checked against what online_ann accepts (a clear error otherwise)."""
    from fresco_bridge.study.paper import StudyError
    from fresco_bridge.updating.registry import updater_options

    accepted = [k for k in updater_options("online_ann") if k not in _ANN_RESERVED]
    for key, _ in pairs:
        if key not in accepted:
            raise StudyError(f"--ann-option {key}: not an online_ann option the study passes on; "
                             f"accepted: {', '.join(accepted)}")
    return tuple(pairs)


def _motions(args: argparse.Namespace, seeds: list[int]) -> list[tuple[str, Any, int]]:
    """(label, motion, seed) per record and seed; every record file is read before any work."""
    from fresco_bridge.integrator import (
        DEMO_DT,
        GroundMotionFormatError,
        kanai_tajimi,
        read_ground_motion,
    )
    from fresco_bridge.study.paper import StudyError

    out: list[tuple[str, Any, int]] = []
    if not args.record:
        for seed in seeds:
            motion = kanai_tajimi(PAPER_PGA_M_S2, duration=SYNTHETIC_DURATION_S, dt=DEMO_DT,
                                  seed=seed)  # fmt: skip
            out.append((f"synthetic-seed{seed}", motion, seed))
        return out
    for path in args.record:
        try:
            motion = read_ground_motion(path).scaled_to_pga(PAPER_PGA_M_S2)
        except FileNotFoundError:
            raise StudyError(f"--record {path}: no such file") from None
        except (GroundMotionFormatError, ValueError, OSError) as exc:
            raise StudyError(f"--record {path}: {exc}") from None
        if motion.dt != DEMO_DT:
            motion = motion.resampled(DEMO_DT)
        out.extend((path.name, motion, seed) for seed in seeds)
    return out


def _run(args: argparse.Namespace) -> int:
    from fresco_bridge.progress import ProgressBar
    from fresco_bridge.study.paper import RunSpec, StudyError, available_cases, run_study
    from fresco_bridge.study.report import (
        markdown_tables,
        score_targets,
        summary_table,
        targets_markdown,
        write_figures,
    )

    seeds = args.seed or [1]
    cases = available_cases() if args.cases is None else tuple(
        c.strip() for c in args.cases.split(",") if c.strip())  # fmt: skip
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        raise StudyError(f"--cases: unknown case(s) {', '.join(unknown)}; known: "
                         f"{', '.join(CASES)}")  # fmt: skip
    runs = [
        RunSpec(label, motion, specimen, noise, seed, args.steps, args.ann_iterations,
                args.pretrain_iterations, _ann_options(args.ann_option), causality,
                args.integrator)
        for label, motion, seed in _motions(args, seeds)
        for specimen in (args.specimen or ["bwbn"])
        for noise in (args.noise or [0.0])
        for causality in dict.fromkeys(args.causality or ["same-step"])
    ]
    try:
        args.out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise StudyError(f"--out {args.out}: cannot create the directory: {exc}") from None
    n_tasks = len(runs) * 2 * len({"reference", *cases})
    print(f"fresco-bridge study paper: {len(runs)} run(s) x 2 layouts x "
          f"{len({'reference', *cases})} cases = {n_tasks} simulations, written to "
          f"{args.out}/", file=sys.stderr, flush=True)
    with ProgressBar("cases", n_tasks) as bar:
        results = run_study(runs, cases, workers=args.workers, scheduler=args.scheduler,
                            progress=bar)
    documents = []
    for (document, histories), run in zip(results, runs, strict=True):
        run_dir = args.out / run.label
        run_dir.mkdir(exist_ok=True)
        (run_dir / "study.json").write_text(json.dumps(document, indent=2), encoding="utf-8")
        table = markdown_tables(document)
        (run_dir / "table.md").write_text(table, encoding="utf-8")
        if not args.no_plots:
            write_figures(document, histories, run_dir)
        print(table)
        documents.append(document)
    targets = score_targets(documents)
    (args.out / "summary.json").write_text(
        json.dumps({"runs": documents, "targets": targets}, indent=2), encoding="utf-8")
    summary = summary_table(documents)
    verdicts = targets_markdown(targets)
    (args.out / "summary.md").write_text(f"{summary}\n{verdicts}", encoding="utf-8")
    print(summary)
    print(f"wrote {args.out}/summary.json, summary.md and one directory per run (study.json, "
          f"table.md"
          f"{', PNGs' if not args.no_plots else ''})", file=sys.stderr)
    print(verdicts)
    return 0
