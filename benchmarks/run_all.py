"""Run every benchmark of this package, or one: what ``make bench`` runs.

    python -m benchmarks.run_all [--quick] [--only NAME]

``--quick`` runs each benchmark's short version (a smoke run: it works, the figures are not the
ones BENCHMARKS.md reports); without it each runs as BENCHMARKS.md's figures were measured, which
takes hours. Every module of ``benchmarks/`` is either listed in ``BENCHMARKS`` or in ``HELPERS``:
a new script that is in neither makes this runner fail, so none is forgotten.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
import traceback
from pathlib import Path

BENCHMARKS: dict[str, str] = {
    "step_path": "Step cost and scaling",
    "opensees_bridge": "Step cost and scaling",
    "models": "Step cost and scaling",
    "modbus_adapter": "Modbus adapter",
    "telemetry": "Telemetry",
    "safety": "Safety layer",
    "fuzz": "Fuzz and soak",
    "soak": "Fuzz and soak",
    "tls_memory": "Fuzz and soak",
    "online_improved": "Online updating",
    "online_ann": "Online updating",
    "ann_equivalence": "Online updating",
    "updater_design": "Online updating",
    "updater_measured": "Online updating",
    "twin": "Online updating",
    "diagnosis": "Diagnosis",
    "diagnose_measured": "Diagnosis",
    "diagnosis_speed": "Diagnosis",
    "first_output": "First output of long commands",
    "setups": "Multi-actuator setups",
    "tangent": "Measured tangent",
    "correction": "Displacement correction",
}
"""Benchmark name -> the BENCHMARKS.md section it feeds. The module is ``bench_NAME`` if that
exists, else ``NAME``; each has ``main(argv)`` accepting ``--quick``."""

HELPERS: dict[str, str] = {
    "_step_peers": ("the peer processes of bench_opensees_bridge (and the message sequence "
                    "bench_step_path replays): not a benchmark itself"),
    "_shared": "where ../shared is, for the benchmarks that read its measured data",
    "_tangent_peer": "the OpenSeesPy processes of bench_tangent and bench_setups",
    "run_all": "this runner",
}
"""Modules of ``benchmarks/`` that are not benchmarks, and why."""

HERE = Path(__file__).resolve().parent


class UnlistedBenchmarkError(RuntimeError):
    """A script in ``benchmarks/`` that this runner does not know."""


def module_name(name: str) -> str:
    """``benchmarks.bench_NAME`` or ``benchmarks.NAME``, whichever exists."""
    stem = f"bench_{name}" if (HERE / f"bench_{name}.py").is_file() else name
    return f"benchmarks.{stem}"


def check_listed() -> None:
    """Every module here is a listed benchmark or a listed helper."""
    known = {module_name(n).rpartition(".")[2] for n in BENCHMARKS} | set(HELPERS) | {"__init__"}
    unlisted = sorted(p.stem for p in HERE.glob("*.py") if p.stem not in known)
    if unlisted:
        raise UnlistedBenchmarkError(
            f"benchmarks/run_all.py: {', '.join(unlisted)} in neither BENCHMARKS nor HELPERS")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="benchmarks.run_all", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="each benchmark's short version")
    parser.add_argument("--only", choices=tuple(BENCHMARKS), help="run this benchmark alone")
    args = parser.parse_args(argv)
    check_listed()
    names = [args.only] if args.only else list(BENCHMARKS)
    failed = []
    for name in names:
        print(f"=== {name} (BENCHMARKS.md, \"{BENCHMARKS[name]}\") ===", flush=True)
        started = time.perf_counter()
        try:
            rc = importlib.import_module(module_name(name)).main(["--quick"] if args.quick else [])
        except SystemExit as exc:  # argparse and the CLI-driving benchmarks exit
            rc = exc.code
            if isinstance(rc, str):  # SystemExit("message"): exit status 1, as Python's
                print(rc, file=sys.stderr)
                rc = 1
        except Exception:  # one broken benchmark must not hide the others
            traceback.print_exc()
            rc = 1
        if rc not in (None, 0):
            failed.append(name)
        print(f"=== {name}: {'FAILED' if rc not in (None, 0) else 'done'} in "
              f"{time.perf_counter() - started:.1f} s ===", flush=True)
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
