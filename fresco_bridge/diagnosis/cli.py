"""``fresco-bridge diagnose`` and ``diagnose-bench``: parsers and handlers.

Bad input (a record, a baseline file, an option) is one line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import tomllib
from dataclasses import replace
from pathlib import Path
from typing import Any

from ..element_history import vocabulary
from ..progress import status
from .load import UNITS, DiagnosisInputError, Record, load_record
from .names import AUTO, AUTO_FAMILIES, BASELINES

__all__ = ["COMMANDS", "add_diagnosis_parsers", "diagnosis_command", "read_baseline"]

COMMANDS = frozenset({"diagnose", "diagnose-bench"})
_TOML_NAMES = {
    "bilinear": ("k0", "fy", "alpha"),
    "bouc-wen": ("k0", "fy", "alpha", "n", "beta", "gamma"),
    "bwbn": ("k0", "fy", "alpha", "n", "beta", "gamma", "zeta_s", "psi0", "q", "p", "delta_psi",
             "delta_nu", "delta_eta"),
    "menegotto-pinto": ("k0", "fy", "alpha", "R0", "cR1", "cR2"),
    "steel02": ("k0", "fy", "alpha", "R0", "cR1", "cR2", "a1"),
    "isotropic-bilinear": ("k0", "fy", "alpha", "q_iso", "p_sat"),
    "elastic": ("k",),
}
"""A PARAMS.toml's parameters per kind (``steel02``: a3 = a1, a2 = a4 = 1; only a1/a2**0.8
enters)."""


def add_diagnosis_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``diagnose`` and ``diagnose-bench`` to the top-level sub-parsers."""
    units = "; ".join(f"{q}: {', '.join(u)}" for q, u in UNITS.items())
    p = sub.add_parser(
        "diagnose", help="where a test departs from its simulation, which unmodelled effect "
                         "causes it, and how far the gap shrinks once it is added")
    p.add_argument("record", type=Path, nargs="+",
                   help="a bridge run directory, or a CSV whose header names time, "
                        "meas_force and a displacement (accepted names: "
                        f"{vocabulary().replace('%', '%%')}; without cmd_disp the record has "
                        "no command channel); several records of one device with "
                        "--same-device")
    p.add_argument("--baseline", default=AUTO,
                   help=f"the sim's law: {AUTO} (default: each of "
                        f"{', '.join(AUTO_FAMILIES)} fitted on the calibration part, the one "
                        f"the BIC prefers kept), {', '.join(BASELINES)}, or a PARAMS.toml "
                        "(kind, [params], fit = true|false)")
    p.add_argument("--site", default=None, help="the site to diagnose (records with several)")
    p.add_argument("--against", type=Path, default=None, metavar="RUN",
                   help="a run directory of the same record without displacement correction: "
                        "report the interface gap (measured displacement vs the integrator's "
                        "target) of both runs and the fraction the correction closed (a run "
                        "with correction lines reports its own gap without it)")
    p.add_argument("--json", type=Path, default=None, metavar="OUT",
                   help="write the diagnosis as JSON (schema: docs/diagnosis.md)")
    p.add_argument("--report", type=Path, default=None, metavar="DIR",
                   help="write plots, summary.txt and diagnosis.json into DIR")
    p.add_argument("--units", default=None,
                   help=f"units of a CSV as disp=U,force=U,time=U ({units}); default mm,kN,s")
    p.add_argument("--noise-floor", type=float, default=None, metavar="PCT",
                   help="withheld gap (NRMS %%) below which the verdict is none (default 1)")
    p.add_argument("--no-command", action="store_true",
                   help="the record has no command channel: its displacement (meas_disp, or "
                        "else cmd_disp) is the measured one; interface effects (delay, "
                        "amplitude, undershoot) are reported as not identifiable. Detected "
                        "without the flag when there is no cmd_disp column")
    p.add_argument("--same-device", action="store_true",
                   help="the records are tests of one device: one law fitted on all their "
                        "calibration parts, each record diagnosed against it, the effects "
                        "consistent across them reported with each record's departures")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")

    b = sub.add_parser("diagnose-bench",
                       help="generate records with known effects on the simulated rig and "
                            "diagnose them blind: confusion matrix, top-1, magnitude errors")
    b.add_argument("--n", type=int, default=55, help="number of records (default 55)")
    b.add_argument("--seed", type=int, default=1, help="bench seed (default 1)")
    b.add_argument("--steps", type=int, default=None,
                   help="samples per record (default 3000; --independent: drawn, 1500-6000)")
    b.add_argument("--workers", type=int, default=None,
                   help="local worker processes (default: one per core; 1 = serial)")
    b.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on a Dask cluster, e.g. tcp://127.0.0.1:8786")
    b.add_argument("--realism", action="store_true",
                   help="harder records: effects in the rig's physical forms (servo lag, "
                        "compliant frame, other pinching/degradation laws), a Menegotto-Pinto "
                        "specimen in a third of the records, varied noise")
    b.add_argument("--independent", action="store_true",
                   help="records from an independent generator (own specimens and effect "
                        "forms, no code shared with the rig; a fifth carry two effects)")
    b.add_argument("--json", type=Path, default=None, metavar="OUT",
                   help="write every record's result and the summary as JSON")
    b.add_argument("--records", type=Path, default=None, metavar="DIR",
                   help="keep the generated records in DIR and reuse them on the next run "
                        "(a realism record can take minutes to generate)")
    b.add_argument("--no-progress", action="store_true", help="no progress bar")


def read_baseline(text: str) -> tuple[str, dict[str, float], bool]:
    """(kind, given parameters in fitting names, fit?) from ``--baseline``."""
    if text == AUTO or text in BASELINES:
        return text, {}, True
    path = Path(text)
    if path.suffix != ".toml":
        raise DiagnosisInputError(
            f"--baseline: unknown baseline {text!r}; choose {AUTO}, {', '.join(BASELINES)} "
            "or a PARAMS.toml file")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise DiagnosisInputError(f"{path}: cannot read: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise DiagnosisInputError(f"{path}: not valid TOML: {exc}") from None
    kind = data.get("kind")
    if kind not in BASELINES:
        raise DiagnosisInputError(f"{path}: kind: must be one of {', '.join(BASELINES)} "
                                  f"(got {kind!r})")
    unknown_keys = set(data) - {"kind", "params", "fit"}
    if unknown_keys:
        raise DiagnosisInputError(f"{path}: unknown key(s) {', '.join(sorted(unknown_keys))} "
                                  "(allowed: kind, params, fit)")
    fit = data.get("fit", True)
    if not isinstance(fit, bool):
        raise DiagnosisInputError(f"{path}: fit: must be true or false (got {fit!r})")
    params = data.get("params", {})
    if not isinstance(params, dict):
        raise DiagnosisInputError(f"{path}: params: must be a table")
    allowed = _TOML_NAMES[kind]
    for name, value in params.items():
        if name not in allowed:
            raise DiagnosisInputError(f"{path}: params.{name}: unknown for {kind} "
                                      f"(allowed: {', '.join(allowed)})")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise DiagnosisInputError(f"{path}: params.{name}: must be a number (got {value!r})")
    if not fit:
        missing = [n for n in allowed if n not in params]
        if missing:
            raise DiagnosisInputError(f"{path}: fit = false needs every parameter; missing "
                                      f"{', '.join(missing)}")
    values = {k: float(v) for k, v in params.items() if k not in ("beta", "gamma")}
    if "beta" in params or "gamma" in params:
        if not ("beta" in params and "gamma" in params):
            raise DiagnosisInputError(f"{path}: params: give beta and gamma together")
        total = float(params["beta"]) + float(params["gamma"])
        if total <= 0.0:
            raise DiagnosisInputError(f"{path}: params: beta + gamma must be > 0 (got {total})")
        values["bg_sum"] = total
        values["beta_share"] = float(params["beta"]) / total
    return kind, values, fit


def _diagnose(args: argparse.Namespace) -> int:
    kind, params, fit = read_baseline(args.baseline)
    if args.noise_floor is not None and not args.noise_floor > 0.0:
        raise DiagnosisInputError(f"--noise-floor: must be > 0 (got {args.noise_floor})")
    if len(args.record) > 1 and not args.same_device:
        raise DiagnosisInputError(f"{len(args.record)} records given: add --same-device if "
                                  "they are tests of one device, or diagnose them one by one")
    if args.same_device and len(args.record) < 2:
        raise DiagnosisInputError("--same-device needs two or more records of the device")
    if args.against is not None and (args.same_device or not args.record[0].is_dir()):
        raise DiagnosisInputError("--against compares two run directories of one record: give "
                                  "one run directory (not a CSV, not --same-device)")
    records = []
    for path in args.record:
        status(f"diagnose: reading {path}" + (f" (site {args.site})" if args.site else ""))
        records.append(load_record(path, site=args.site, units=args.units,
                                   no_command=args.no_command))
    from .options import Policy
    from .verdict import NOISE_FLOOR_PCT, Options

    options = Options(baseline=kind, baseline_params=params, fit_baseline=fit,
                      policy=Policy(noise_floor_pct=args.noise_floor or NOISE_FLOOR_PCT))
    if args.same_device:
        status(f"diagnose: {len(records)} records of one device; one law fitted on all their "
               "calibration parts, then each candidate effect on all of them")
        return _device(args, records, options)
    record = records[0]
    baseline = ("choosing the baseline law by BIC, then fitting each candidate effect"
                if kind == AUTO else f"fitting the {kind} baseline, then each candidate effect")
    status(f"diagnose: {record.size} samples; {baseline}")
    from ..progress import ProgressBar
    from .outputs import summary, write_json, write_report
    from .verdict import diagnose

    gap = None
    if args.record[0].is_dir():  # read before the minutes of fitting: a bad --against fails now
        from .interface_gap import interface_gap

        gap = interface_gap(args.record[0], args.site, args.against)
    with ProgressBar("diagnose", 0, enabled=not args.no_progress) as bar:  # total: diagnose
        result = replace(diagnose(record, options, progress=bar), interface_gap=gap)
    print(summary(result))
    if args.json is not None:
        write_json(result, args.json)
        print(f"wrote     {args.json}")
    if args.report is not None:
        files = write_report(result, args.report)
        print(f"wrote     {args.report}/ ({len(files)} files: "
              f"{', '.join(sorted(p.name for p in files))})")
    return 0


def _device(args: argparse.Namespace, records: list[Record], options: Any) -> int:
    from .multi import diagnose_device, summary_device
    from .outputs import to_json, write_report

    doc = diagnose_device(records, options)
    print(summary_device(doc))
    if args.json is not None:
        args.json.write_text(to_json(doc) + "\n", encoding="utf-8")
        print(f"wrote     {args.json}")
    if args.report is not None:
        args.report.mkdir(parents=True, exist_ok=True)
        for i, (path, result) in enumerate(zip(args.record, doc["results"], strict=True)):
            write_report(result, args.report / f"{i + 1}-{path.stem}")
        (args.report / "summary.txt").write_text(summary_device(doc) + "\n", encoding="utf-8")
        (args.report / "device.json").write_text(to_json(doc) + "\n", encoding="utf-8")
        print(f"wrote     {args.report}/ (summary.txt, device.json, one directory per "
              "record)")
    return 0


def _bench(args: argparse.Namespace) -> int:
    if args.n < 1:
        raise DiagnosisInputError(f"--n: must be >= 1 (got {args.n})")
    if args.steps is not None and args.steps < 200:
        raise DiagnosisInputError(f"--steps: must be >= 200 (got {args.steps})")
    if args.realism and args.independent:
        raise DiagnosisInputError("--realism and --independent: choose one generator")
    samples = args.steps or ("1500-6000" if args.independent else 3000)
    generated = "by the independent generator" if args.independent else "on the simulated rig"
    status(f"diagnose-bench: {args.n} record(s) of {samples} samples, seed {args.seed}"
            f"{', realism' if args.realism else ''}: each generated {generated}"
            + ("" if args.records is None else f" (or reused from {args.records})")
            + " and diagnosed blind")
    from ..progress import ProgressBar
    from ..sweeps import run_sweep

    bench = _bench_module()
    bench_items, diagnose_one = bench.bench_items, bench.diagnose_one
    format_bench, summarise_bench = bench.format_bench, bench.summarise_bench

    items = bench_items(args.n, args.seed, args.steps, args.realism,
                        None if args.records is None else str(args.records),
                        independent=args.independent)
    started = time.perf_counter()
    with ProgressBar("diagnose-bench", len(items), enabled=not args.no_progress) as bar:
        rows = run_sweep(diagnose_one, items, workers=args.workers, scheduler=args.scheduler,
                         progress=bar)
    wall = time.perf_counter() - started
    result = summarise_bench(rows)
    print(format_bench(result, args.seed, wall, realism=args.realism,
                       independent=args.independent))
    if args.json is not None:
        doc: dict[str, Any] = {"seed": args.seed, "n": args.n, "steps": args.steps,
                               "realism": args.realism, "independent": args.independent,
                               "wall_seconds": wall, "summary": result, "records": rows}
        args.json.write_text(json.dumps(doc, indent=2, default=float) + "\n", encoding="utf-8")
        print(f"wrote {args.json}")
    return 0


def _bench_module() -> Any:
    """The bench generators (``benchmarks/diagnosis``), imported only when the bench runs: they
    are not part of the product and live beside it in the repository checkout."""
    import importlib

    try:
        return importlib.import_module("benchmarks.diagnosis.bench")
    except ModuleNotFoundError as exc:
        if exc.name not in ("benchmarks", "benchmarks.diagnosis"):
            raise
    root = Path(__file__).resolve().parents[2]
    if not (root / "benchmarks" / "diagnosis" / "bench.py").is_file():
        raise DiagnosisInputError(
            "diagnose-bench needs the repository checkout: its record generators live in "
            "benchmarks/diagnosis/, not in the installed package")
    sys.path.insert(0, str(root))
    return importlib.import_module("benchmarks.diagnosis.bench")


def diagnosis_command(args: argparse.Namespace) -> int:
    """Run ``diagnose`` or ``diagnose-bench``; bad input -> one line on stderr, exit 2."""
    from ..sweeps import SweepError

    try:
        if args.command == "diagnose":
            return _diagnose(args)
        return _bench(args)
    except DiagnosisInputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except SweepError as exc:
        print(f"error: diagnose-bench: {exc}", file=sys.stderr)
        return 1
