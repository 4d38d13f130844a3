"""Diagnosis speed per record: CPU and wall seconds of ``diagnose`` at 3000 and 30 000 samples.

Issue 29's targets: a 3000-sample record in at most 10 s (median) and 30 s (worst), a 30 000-
sample one in at most 60 s, on this (shared, loaded) machine. Wall time on a loaded machine
measures the neighbours as much as the code, so each record reports both: CPU seconds of this
process (``time.process_time``: BLAS is held to one thread by the fit, the JIT drives are
single-threaded) and wall seconds. The records are the plain bench's (``synth``, the rig) and
the independent bench's (``independent``, specimens and effects sharing no code with the rig),
one per effect class listed below, generated before the clock starts; one warm-up diagnosis
loads the JIT drives first (a cold cache compiles them: tens of seconds, once per install).

    python -m benchmarks.bench_diagnosis_speed [--quick] [--json OUT]

Feeds BENCHMARKS.md, "Diagnosis" (speed). ``--quick``: two 3000-sample records and one of
30 000, a smoke run.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from typing import Any

from benchmarks.diagnosis.independent import independent_record
from benchmarks.diagnosis.synth import synthetic_record
from fresco_bridge.diagnosis.load import Record
from fresco_bridge.diagnosis.verdict import diagnose

PLAIN = ("friction", "backlash", "pinching", "degradation", "actuator_delay", "none")
INDEPENDENT = ("friction", "backlash", "pinching", "actuator_undershoot", "none")
SEED = 2026


def _records(steps: int, quick: bool) -> list[tuple[str, Record]]:
    plain = PLAIN[:2] if quick else PLAIN
    out = [(f"plain {e}", synthetic_record(e, SEED * 100_003 + i, steps=steps).record)
           for i, e in enumerate(plain)]
    if not quick:
        out += [(f"independent {e}",
                 independent_record(e, SEED * 100_003 + 50 + i, steps=steps).record)
                for i, e in enumerate(INDEPENDENT)]
    return out


def _time(record: Record) -> tuple[float, float, str]:
    cpu, wall = time.process_time(), time.perf_counter()
    result = diagnose(record).to_json()
    return (time.process_time() - cpu, time.perf_counter() - wall,
            str(result["verdict"]["effect"]))


def run(quick: bool) -> dict[str, Any]:
    """Every record's CPU and wall seconds, and their median and worst per length."""
    _time(synthetic_record("none", SEED, steps=600).record)  # JIT drives loaded (or compiled)
    lengths = (3000, 30_000)
    out: dict[str, Any] = {}
    for steps in lengths:
        records = _records(steps, quick)[: 1 if quick and steps > 3000 else None]
        rows: list[dict[str, Any]] = []
        cpus: list[float] = []
        walls: list[float] = []
        for name, record in records:
            cpu, wall, verdict = _time(record)
            cpus.append(cpu)
            walls.append(wall)
            rows.append({"record": name, "samples": record.size, "cpu_s": cpu, "wall_s": wall,
                         "verdict": verdict})
            print(f"{steps:>6} {name:<32} {record.size:>6} samples  CPU {cpu:6.1f} s  "
                  f"wall {wall:6.1f} s  -> {verdict}", flush=True)
        out[str(steps)] = {"records": rows,
                           "cpu_median_s": statistics.median(cpus), "cpu_worst_s": max(cpus),
                           "wall_median_s": statistics.median(walls),
                           "wall_worst_s": max(walls)}
        print(f"{steps:>6} samples: CPU median {statistics.median(cpus):.1f} s, worst "
              f"{max(cpus):.1f} s; wall median {statistics.median(walls):.1f} s, worst "
              f"{max(walls):.1f} s", flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="benchmarks.bench_diagnosis_speed",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="a smoke run (three records)")
    parser.add_argument("--json", help="write the figures here")
    args = parser.parse_args(argv)
    figures = run(args.quick)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(figures, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
