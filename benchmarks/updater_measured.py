"""Every updater on a *measured* device: the banded rotary friction damper (BRFD).

The study's specimens are simulated, and one of them (BWBN) is the rig's own law. A real device
lies in nobody's family, so this is the out-of-family test a lab cares about most. The BRFD
data (``../shared/data/measured/rotary_friction_damper_BRFD``, 1024 Hz, in and kip) hold one
device at one band tension (30 lb) under four earthquake displacement histories (Imperial Valley
and Kocaeli, each at DBE and MCE) and sinusoidal characterisation tests. Each *pair* makes one
history the tested element (the source: its d and F, observed step by step) and another the twin
(its d; its measured F only for scoring), row i of both being step i (the longer is cut to the
shorter, the twin's tail dropped), as ``updater replay`` defines it:

* same motion, other intensity (DBE -> MCE: the twin goes 2.3x (Imperial Valley) or 2.0x
  (Kocaeli) further than the tested element; MCE -> DBE: less far);
* other motion, same intensity level (Imperial Valley <-> Kocaeli);
* with ``--self``, also each history as its own twin (the paper layout, ``SELF_PAIRS``).

The offline database is the first 2500 steps of the 0.25 Hz, 1 in sine (the paper's Step 1 from
existing test data: a conventional characterisation test of the same device). Every history is
thinned to every ``--decimate``-th sample (default 8: 128 Hz, 3418-3587 steps a history, the
size of the study's records). Cases, each the registry's defaults, run as a user would, through
``fresco-bridge updater pretrain|replay``:

* ``calibrated_bilinear`` (``none --offline``, the study's ``conventional_calibrated``);
* ``offline_ann`` and ``online_ann`` (``--model``: the network pre-trained once on the offline
  database, seed 0, 1000 LM iterations);
* ``online_ukf`` (the paper's start values) and ``online_ukf_calibrated`` (``--offline``: start
  at the calibrated Bilinear, the paper's covariances);
* ``online_improved`` (``--offline``).

    python -m benchmarks.updater_measured [--quick] [-o out/updater_measured] [--workers 2]
        [--only SUBSTRING] [--decimate 8] [--lag] [--self] [--cases a,b]

Prints one table per pair, a summary and the verdict on the measured friction damper's target
(``online_improved``'s RMS below the calibrated Bilinear's on every pair, the bad pairs named),
and writes ``summary.json`` (the verdict under ``target``). Nothing is tuned to these
data: they were first run with the options above, decided before. Needs ``../shared`` (exits
with a message naming the missing directory). Feeds BENCHMARKS.md, "Online updating" (the
measured friction damper). ``--quick``: one pair, every 128th sample, one worker, into a
temporary directory (not ``-o``), a smoke run.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import gzip
import io
import json
import math
import tempfile
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._shared import MEASURED, require_shared
from fresco_bridge.cli import main as cli_main
from fresco_bridge.updating.histories import Units

BRFD = MEASURED / "rotary_friction_damper_BRFD"
UNITS = "in,kip"
KN_PER_FORCE_UNIT = Units.parse(UNITS).to_kn
OFFLINE_RECORD = "0.25Hz30lbtension1amplitude"
OFFLINE_STEPS = 2500
IV_DBE, IV_MCE = "ImperialValleyDBE", "ImperialValleyMCE"
KO_DBE, KO_MCE = "KocaeliDBE", "KocaeliMCE"
PAIRS: tuple[tuple[str, str], ...] = (
    (IV_DBE, IV_MCE), (IV_MCE, IV_DBE), (KO_DBE, KO_MCE), (KO_MCE, KO_DBE),
    (IV_DBE, KO_DBE), (KO_DBE, IV_DBE), (IV_MCE, KO_MCE), (KO_MCE, IV_MCE),
)
"""(source, twin): four of the same motion at the other intensity, four of the other motion."""
SELF_PAIRS: tuple[tuple[str, str], ...] = tuple((r, r) for r in (IV_DBE, IV_MCE, KO_DBE, KO_MCE))
"""The paper layout (``--self``): the twin *is* the tested element, under identical loading, so
its error shows how much of the measured force no updater predicts even from its own past."""
CASES = ("calibrated_bilinear", "offline_ann", "online_ukf", "online_ukf_calibrated",
         "online_ann", "online_improved")


@dataclass(frozen=True)
class Files:
    """The converted CSVs (``time,disp,force``, in and kip) and the pre-trained model file."""

    root: Path
    offline: Path
    model: Path

    def history(self, record: str) -> Path:
        return self.root / f"{record}.csv"

    def twin(self, source: str, twin: str) -> Path:
        """The twin's CSV, cut to the source's length when it is longer (see ``prepare``)."""
        return self.root / f"{twin}_for_{source}.csv"


def load_brfd(record: str, decimate: int) -> np.ndarray:
    """(time s, disp in, force kip) rows of a dataset-3 record, every ``decimate``-th sample."""
    path = BRFD / f"dataset-3_{record}.json.gz"
    data = np.array(json.loads(gzip.decompress(path.read_bytes()))["data"], dtype=np.float64)
    return data[::decimate, :3]


def _write_csv(path: Path, rows: np.ndarray) -> Path:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["time", "disp", "force"])
    for t, d, f in rows:
        w.writerow([repr(float(t)), repr(float(d)), repr(float(f))])
    path.write_text(buf.getvalue(), encoding="utf-8")
    return path


def prepare(out: Path, decimate: int, pairs: Sequence[tuple[str, str]]) -> Files:
    """Convert the records (each pair's twin cut to its source's length), cut the offline
    database, pre-train the network once: every file exists before any replay runs."""
    out.mkdir(parents=True, exist_ok=True)
    rows = {r: load_brfd(r, decimate) for r in sorted({r for p in pairs for r in p})}
    for record, data in rows.items():
        _write_csv(out / f"{record}.csv", data)
    for source, twin in pairs:
        _write_csv(out / f"{twin}_for_{source}.csv", rows[twin][: len(rows[source])])
    offline_rows = load_brfd(OFFLINE_RECORD, decimate)[:OFFLINE_STEPS]
    offline = _write_csv(out / "offline.csv", offline_rows)
    model = out / "brfd.pt"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        rc = cli_main(["updater", "pretrain", str(offline), "-o", str(model), "--units", UNITS,
                       "--seed", "0", "--plot", str(out / "brfd_pretrain.png")])
    if rc != 0:
        raise RuntimeError(f"updater pretrain failed on {offline} (exit {rc})")
    return Files(out, offline, model)


def case_arguments(case: str, files: Files) -> list[str]:
    """The ``updater replay`` arguments of one case (registry defaults only)."""
    off, model = str(files.offline), str(files.model)
    return {
        "calibrated_bilinear": ["--updater", "none", "--offline", off],
        "offline_ann": ["--updater", "offline_ann", "--model", model],
        "online_ukf": ["--updater", "online_ukf"],
        "online_ukf_calibrated": ["--updater", "online_ukf", "--offline", off],
        "online_ann": ["--updater", "online_ann", "--model", model],
        "online_improved": ["--updater", "online_improved", "--offline", off],
    }[case]


def pair_name(source: str, twin: str) -> str:
    return f"{source}->{twin}"


def run_case(files: Files, source: str, twin: str, case: str, lag: bool) -> dict[str, Any]:
    """One ``updater replay`` (the twin cut to the source's length), its JSON summary."""
    src, twin_path = files.history(source), files.twin(source, twin)
    tag = f"{source}-{twin}-{case}{'-lag' if lag else ''}"
    pred = files.root / f"pred-{tag}.csv"
    argv = ["updater", "replay", "--source", str(src), "--twin", str(twin_path),
            "--units", UNITS, "--quiet", "-o", str(pred), *case_arguments(case, files),
            *(["--lag"] if lag else [])]
    cpu = time.process_time()
    with contextlib.redirect_stdout(io.StringIO()) as printed:
        rc = cli_main(argv)
    cpu = time.process_time() - cpu
    if rc != 0:
        return {"pair": pair_name(source, twin), "case": case, "error": f"exit {rc}",
                "printed": printed.getvalue()}
    doc = json.loads(pred.with_suffix(".json").read_text(encoding="utf-8"))
    true = np.array([float(r["force_true"]) for r in _dict_rows(pred)])
    return {"pair": pair_name(source, twin), "case": case, "steps": doc["steps"],
            "maeth_kN": doc["metrics_kN"]["maeth"], "rms_kN": doc["metrics_kN"]["rms"],
            "twin_peak_kN": float(np.max(np.abs(true))) * KN_PER_FORCE_UNIT,
            "update_ms": doc["update_ms"], "wall_s": doc["wall_seconds"], "cpu_s": cpu,
            "bounded": bool(math.isfinite(doc["metrics_kN"]["maeth"]))}


def _dict_rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _task(job: tuple[Files, str, str, str, bool]) -> dict[str, Any]:
    return run_case(*job)


def table(rows: list[dict[str, Any]], key: str = "maeth_kN") -> str:
    """One markdown table: a row per pair, ``key`` (MAETH or RMS, kN) per case and its
    reduction against the calibrated Bilinear."""
    by_pair: dict[str, dict[str, dict[str, Any]]] = {}
    for r in rows:
        by_pair.setdefault(r["pair"], {})[r["case"]] = r
    cases = [c for c in CASES if any(c in v for v in by_pair.values())]
    what = {"maeth_kN": "MAETH kN", "rms_kN": "RMS kN"}.get(key, key)
    head = f"| {what}: source -> twin | twin peak kN | " + " | ".join(cases) + " |"
    lines = [head, "|" + "---|" * (len(cases) + 2)]
    for pair, got in by_pair.items():
        base = got.get("calibrated_bilinear", {}).get(key)
        peak = next((g["twin_peak_kN"] for g in got.values() if "twin_peak_kN" in g), math.nan)
        cells = []
        for c in cases:
            g = got.get(c)
            if g is None:
                cells.append("")
            elif "error" in g:
                cells.append(g["error"])
            elif base is None or c == "calibrated_bilinear":
                cells.append(f"{g[key]:.3f}")
            else:
                cells.append(f"{g[key]:.3f} ({100 * (1 - g[key] / base):+.0f} %)")
        lines.append(f"| {pair} | {peak:.2f} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def rms_target(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The target: ``online_improved``'s RMS below the calibrated Bilinear's on every pair run
    with both (the ``--self`` pairs are the paper layout, not scored); a failed case is bad."""
    by_pair: dict[str, dict[str, dict[str, Any]]] = {}
    for r in rows:
        by_pair.setdefault(r["pair"], {})[r["case"]] = r
    own = {pair_name(*p) for p in SELF_PAIRS}
    scored, bad = 0, []
    for pair, got in by_pair.items():
        mine, base = got.get("online_improved"), got.get("calibrated_bilinear")
        if pair in own or mine is None or base is None:
            continue
        scored += 1
        if "error" in mine or "error" in base:
            bad.append(f"{pair} ({mine.get('error') or base.get('error')})")
        elif not mine["rms_kN"] < base["rms_kN"]:
            bad.append(f"{pair} (RMS {mine['rms_kN']:.3f} kN, Bilinear {base['rms_kN']:.3f} kN)")
    verdict = "not run" if not scored else ("missed" if bad else "met")
    return {"target": "online_improved RMS below the calibrated Bilinear on every pair",
            "verdict": verdict, "pairs": scored, "meeting": scored - len(bad), "bad": bad}


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--out", type=Path, default=Path("out/updater_measured"))
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--only", default=None, help="substring of the pair names to run")
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--decimate", type=int, default=8)
    parser.add_argument("--lag", action="store_true", help="the twin knows the source to i-1")
    parser.add_argument("--self", dest="self_pairs", action="store_true",
                        help="also each history as its own twin (the paper layout)")
    parser.add_argument("--quick", action="store_true",
                        help="one pair, every 128th sample, one worker, a temporary directory")
    args = parser.parse_args(argv)
    require_shared(BRFD, "benchmarks.updater_measured")
    if args.quick:
        args.decimate, args.workers = max(args.decimate, 128), 1
        args.only = args.only or pair_name(KO_DBE, KO_MCE)
        args.out = Path(tempfile.mkdtemp(prefix="updater-measured-"))
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    unknown = sorted(set(cases) - set(CASES))
    if unknown or args.decimate < 1:
        parser.error(f"--cases: unknown {unknown}; known {CASES}" if unknown
                     else "--decimate must be >= 1")
    pairs = [p for p in PAIRS + (SELF_PAIRS if args.self_pairs else ())
             if args.only is None or args.only in pair_name(*p)]
    start = time.perf_counter()
    files = prepare(args.out, args.decimate, pairs)
    print(f"prepared {len(pairs)} pairs and the model in {time.perf_counter() - start:.1f} s")
    jobs = [(files, s, t, c, args.lag) for s, t in pairs for c in cases]
    # the slowest first, so the pool's tail is short
    jobs.sort(key=lambda j: j[3] != "online_ann")
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        rows = list(pool.map(_task, jobs))
    order = {pair_name(*p): i for i, p in enumerate(pairs)}
    rows.sort(key=lambda r: (order[r["pair"]], CASES.index(r["case"])))
    print(table(rows))
    print()
    print(table(rows, "rms_kN"))
    for r in rows:
        if "error" not in r:
            print(f"{r['pair']:40s} {r['case']:22s} MAETH {r['maeth_kN']:7.3f} kN  RMS "
                  f"{r['rms_kN']:6.3f} kN  update median {r['update_ms']['median']:7.3f} ms  "
                  f"p99 {r['update_ms']['p99']:7.3f} ms  wall {r['wall_s']:6.1f} s")
    target = rms_target(rows)
    summary = {"decimate": args.decimate, "lag": args.lag,
               "offline": OFFLINE_RECORD, "offline_steps": OFFLINE_STEPS, "rows": rows,
               "target": target, "wall_s": time.perf_counter() - start}
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {args.out / 'summary.json'} ({summary['wall_s']:.0f} s)")
    print(f"target: {target['target']}: {target['verdict']}"
          + (f", {target['meeting']} of {target['pairs']} pair(s)" if target["pairs"] else "")
          + "".join(f"\n  bad: {b}" for b in target["bad"]))


if __name__ == "__main__":
    main()
