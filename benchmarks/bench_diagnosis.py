"""Diagnosis speed: one law drive per route, and whole diagnoses of 3000 and 30 000 samples.

Routes for one 3000-step Bouc-Wen history (the unit of work of every fit): the scalar model
(``set_trial``/``commit`` in Python) and the JIT drive (``sim_actuator.models.paths``), at the
models' default resolution and at the diagnosis' (``DZ_MAX``); alternated, >= 3 rounds,
min/median. Then ``diagnose`` (every candidate, pairs when triggered) on a 3000-step rig record
and a 30 000-sample one, >= 3 rounds each in process (JIT code already loaded), one cold
``fresco-bridge diagnose`` in a fresh process (imports, JIT cache load) and the JIT compile cost
with an empty cache; then the MR damper's first 30 000 samples (needs ``../shared``; says so
when it is missing), CPU time in a fresh process per round, optionally alternated with another
source tree. Run pinned:

    taskset -c 1 python -m benchmarks.bench_diagnosis [--quick] [--only mr --against TREE]

Feeds BENCHMARKS.md, "Diagnosis" (its speed). ``--quick``: one round, the 3000-step diagnosis
only, no empty-cache compile, the MR damper's first 1000 samples, a smoke run.
"""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

from benchmarks._shared import MEASURED, require_shared
from benchmarks.diagnosis.synth import synthetic_record
from fresco_bridge.diagnosis.model import DZ_MAX
from fresco_bridge.diagnosis.verdict import diagnose
from sim_actuator.models import make_model
from sim_actuator.models.paths import drive, law_vector

ROUNDS = 3
PARAMS = {"k0": 10.0, "fy": 25.0, "alpha": 0.05, "n": 2.0, "beta": 0.6, "gamma": 0.4}


def _scalar(d: np.ndarray, dz_max: float) -> None:
    model = make_model("bouc-wen", **PARAMS)
    model = type(model)(**PARAMS, dz_max=dz_max)  # type: ignore[call-arg]
    for x in d:
        model.set_trial(float(x))
        model.commit()


def _stats(samples: list[float]) -> str:
    return f"min {min(samples):.4g} s, median {statistics.median(samples):.4g} s"


def routes(rounds: int) -> None:
    record = synthetic_record("none", 1, steps=3000).record
    d = record.cmd
    law, vec = law_vector("bouc-wen", PARAMS)
    drive(law, vec, d, 0.0, DZ_MAX)
    times: dict[str, list[float]] = {}
    for _ in range(rounds):
        for name, fn in (
            ("scalar Python, dz_max 0.01", lambda: _scalar(d, 0.01)),
            (f"scalar Python, dz_max {DZ_MAX}", lambda: _scalar(d, DZ_MAX)),
            ("JIT drive, dz_max 0.01", lambda: drive(law, vec, d, 0.0, 0.01)),
            (f"JIT drive, dz_max {DZ_MAX}", lambda: drive(law, vec, d, 0.0, DZ_MAX)),
        ):
            started = time.perf_counter()
            fn()
            times.setdefault(name, []).append(time.perf_counter() - started)
    print("one 3000-step Bouc-Wen history (path of a bench record):")
    for name, samples in times.items():
        print(f"  {name:<28} {_stats(samples)}")
    scalar, jit = f"scalar Python, dz_max {DZ_MAX}", f"JIT drive, dz_max {DZ_MAX}"
    ratio = min(times[scalar]) / min(times[jit])
    print(f"  JIT / scalar speed-up at dz_max {DZ_MAX}: {ratio:.0f}x")


def diagnoses(rounds: int, long: bool = True) -> None:
    cases = [("3000 steps (friction)", synthetic_record("friction", 5, steps=3000).record)]
    if long:
        cases.append(("30 000 samples (backlash, dt 1 ms)",
                      synthetic_record("backlash", 6, steps=30_000, dt=0.001).record))
    for name, record in cases:
        samples = []
        verdict = ""
        for _ in range(rounds):
            started = time.perf_counter()
            result = diagnose(record).to_json()
            samples.append(time.perf_counter() - started)
            verdict = result["verdict"]["effect"]
        print(f"diagnose {name}: {_stats(samples)} (verdict {verdict}, "
              f"{len(result['pairs'])} pairs fitted)")


def console_script() -> str:
    """``module:function`` of the ``fresco-bridge`` console script (pyproject.toml)."""
    with (Path(__file__).resolve().parents[1] / "pyproject.toml").open("rb") as fh:
        return str(tomllib.load(fh)["project"]["scripts"]["fresco-bridge"])


def cold(rounds: int, compile_cost: bool = True) -> None:
    record = synthetic_record("friction", 5, steps=3000).record
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "r.csv"
        assert record.meas_disp is not None
        rows = zip(record.time, record.cmd, record.meas_disp, record.force, strict=True)
        csv.write_text("time,cmd_disp,meas_disp,meas_force\n"
                       + "".join(",".join(repr(float(x)) for x in r) + "\n" for r in rows))
        # the ``fresco-bridge`` console script as pyproject.toml declares it, in a fresh process
        module, _, func = console_script().partition(":")
        exe = [sys.executable, "-c", f"import sys; from {module} import {func}; "
               f"sys.exit({func}(sys.argv[1:]))", "diagnose", str(csv), "--no-progress"]
        walls: list[float] = []
        cpus: list[float] = []
        for _ in range(rounds):
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            started = time.perf_counter()
            subprocess.run(exe, check=True, capture_output=True)
            walls.append(time.perf_counter() - started)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
        print(f"cold CLI run (fresco-bridge diagnose, {module}), 3000 steps (fresh process, JIT "
              f"cache warm): wall {_stats(walls)}; CPU {_stats(cpus)}")
        if not compile_cost:
            return
        env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / "empty-cache"))
        code = ("import time, numpy as np; t=time.perf_counter();"
                "from sim_actuator.models.paths import drive, drive_many, law_vector;"
                "d=np.linspace(0,1,10);"
                "[drive(*law_vector(k, p), d) for k, p in (('bilinear', dict(k0=1.,fy=1.,"
                "alpha=.1)), ('bouc-wen', dict(k0=1.,fy=1.,alpha=.1,n=2.,beta=.5,gamma=.5)))];"
                "l,v=law_vector('bilinear', dict(k0=1.,fy=1.,alpha=.1));"
                "drive_many(l, v[None,:], d[None,:], np.zeros(1));"
                "print(time.perf_counter()-t)")
        out = subprocess.run([sys.executable, "-c", code], env=env, check=True,
                             capture_output=True, text=True).stdout
        print(f"JIT compile of the drives with an empty cache (once per install): "
              f"{float(out):.2f} s")


MR_DAMPER = MEASURED / "mr_damper_dyke_nees2012_1158" / "ransim_u_converted.csv.gz"
MR_SAMPLES = 30_000
_MR_CODE = """
import csv, gzip, io, sys, time
import numpy as np
from fresco_bridge.diagnosis.load import record_from_arrays
from fresco_bridge.diagnosis.verdict import diagnose
rows = list(csv.reader(io.StringIO(gzip.decompress(open(sys.argv[1], 'rb').read()).decode())))
cols = {h: i for i, h in enumerate(rows[0])}
body = np.array([[float(r[cols[k]]) for k in 't D F'.split()] for r in rows[1:] if r and r[0]])
body = body[:int(sys.argv[2])]
warm = record_from_arrays(body[:300, 0], body[:300, 1] * 10.0, body[:300, 2] * 1e-3)
diagnose(warm).to_json()  # JIT code loaded before the clock starts
record = record_from_arrays(body[:, 0], body[:, 1] * 10.0, body[:, 2] * 1e-3, source='mr')
started = time.process_time()
result = diagnose(record).to_json()
print(time.process_time() - started, result['baseline']['kind'], result['verdict']['effect'])
"""


def mr_damper(against: str | None, rounds: int, samples: int = MR_SAMPLES) -> None:
    """The MR damper's first 30 000 samples (cm, N -> mm, kN), every candidate, in a fresh
    process per round (CPU time of the diagnosis alone); with ``against`` (a source tree, e.g.
    ``git archive main``) the same in that tree, alternated round by round."""
    require_shared(MR_DAMPER, "benchmarks.bench_diagnosis mr")
    variants = {"this tree": str(Path(__file__).resolve().parents[1])}
    if against is not None:
        variants["against " + against] = against
    cpus: dict[str, list[float]] = {k: [] for k in variants}
    for _ in range(rounds):
        for name, tree in variants.items():
            env = dict(os.environ, PYTHONPATH=tree)
            out = subprocess.run([sys.executable, "-c", _MR_CODE, str(MR_DAMPER),
                                  str(samples)], env=env, cwd=tree, check=True,
                                 capture_output=True, text=True).stdout.split()
            cpus[name].append(float(out[0]))
            print(f"  {name}: {float(out[0]):.1f} s CPU (baseline {out[1]}, verdict {out[2]})",
                  flush=True)
    for name in variants:
        print(f"MR damper ransim_u, first {samples} samples, diagnosis CPU via {name}: "
              f"{_stats(cpus[name])}")


def main(argv: list[str] | None = None) -> None:
    import argparse

    parser = argparse.ArgumentParser(prog="benchmarks.bench_diagnosis",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=("routes", "diagnoses", "cold", "mr"), default=None)
    parser.add_argument("--against", default=None, metavar="TREE",
                        help="mr: also run this source tree, alternated (e.g. git archive main)")
    parser.add_argument("--quick", action="store_true",
                        help="one round, short records, no empty-cache compile")
    args = parser.parse_args(argv)
    rounds = 1 if args.quick else ROUNDS
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()}")
    sections = {
        "routes": lambda: routes(rounds),
        "diagnoses": lambda: diagnoses(rounds, long=not args.quick),
        "cold": lambda: cold(rounds, compile_cost=not args.quick),
        "mr": lambda: mr_damper(args.against, rounds, 1000 if args.quick else MR_SAMPLES),
    }
    for name, run in sections.items():
        if args.only in (None, name):
            run()


if __name__ == "__main__":
    main()
