"""Run ``fresco-bridge diagnose``, untuned, on every measured test in ``../shared/data/measured``.

The tool itself never reads ``../shared``: this script converts each data set to the tool's CSV
and calls the command as a user would. None of these data sets has a command channel, so each
CSV is ``time,meas_disp,meas_force`` and the tool detects it: the measured displacement drives
the law, the interface effects are reported as not identifiable and the diagnosis speaks for
the specimen and sensor layers only. Quasi-static tests without a time column (RC column,
braces) get a sample index as time (dt = 1 s), so rate effects cannot be judged there.
``--device`` runs ``diagnose --same-device`` on the records of one device instead
(:data:`DEVICES`: the BRFD's four records named in issue 29, one shared law).

    python -m benchmarks.diagnose_measured [--quick] [-o out/measured] [--only NAME]
    python -m benchmarks.diagnose_measured --device BRFD [-o out/measured]

Writes one CSV, one JSON and one report directory per test, and prints a table. Needs
``../shared`` (exits with a message naming the missing directory). Feeds BENCHMARKS.md,
"Diagnosis" (measured devices). ``--quick``: the RC column alone, into a temporary directory
(not ``-o``), a smoke run.
"""

from __future__ import annotations

import argparse
import csv
import gzip
import io
import json
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from benchmarks._shared import MEASURED, require_shared
from fresco_bridge.cli import main as cli_main

DEVICES = {
    "BRFD": ("BRFD dataset-3_ImperialValleyDBE", "BRFD dataset-3_0.5Hz30lbtension1amplitude",
             "BRFD dataset-3_2Hz30lbtension0.5amplitude", "BRFD dataset-3_KocaeliDBE"),
    "BRFD-all": tuple(f"BRFD dataset-3_{n}" for n in (
        "0.25Hz30lbtension1amplitude", "0.5Hz30lbtension1amplitude", "1Hz30lbtension1amplitude",
        "2Hz30lbtension0.5amplitude", "ImperialValleyDBE", "ImperialValleyMCE", "KocaeliDBE",
        "KocaeliMCE")),
}
"""Records of one device for ``--device``: four stories of issue 29, and the whole dataset-3
(same band tension, 30 lb)."""


def _write(path: Path, t: np.ndarray, d: np.ndarray, f: np.ndarray) -> Path:
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["time", "meas_disp", "meas_force"])
        for row in zip(t, d, f, strict=True):
            w.writerow([repr(float(x)) for x in row])
    return path


def tests(out: Path, only: str | None = None) -> Iterator[tuple[str, Path, str, str]]:
    """(name, csv, --units, note) for every measured test (whose name contains ``only``)."""
    def wanted(name: str) -> bool:
        return only is None or only in name

    brfd = MEASURED / "rotary_friction_damper_BRFD"
    for gz in sorted(brfd.glob("*.json.gz")):
        if not wanted("BRFD " + gz.name.removesuffix(".json.gz")):
            continue
        data = np.array(json.loads(gzip.decompress(gz.read_bytes()))["data"], dtype=float)
        name = "BRFD " + gz.name.removesuffix(".json.gz")
        # dataset-3: t, disp [in], friction force [kip]; dataset-4: t, MTS disp [in], force
        path = _write(out / f"{gz.name.removesuffix('.json.gz')}.csv",
                      data[:, 0], data[:, 1], data[:, 2])
        yield name, path, "disp=in,force=kip", "friction damper with backlash (README)"
    mr = MEASURED / "mr_damper_dyke_nees2012_1158"
    for gz in sorted(mr.glob("*.csv.gz")):
        if not wanted(f"MR damper {gz.name.removesuffix('_converted.csv.gz')}"):
            continue
        rows = list(csv.reader(io.StringIO(gzip.decompress(gz.read_bytes()).decode())))
        header = rows[0]
        cols = {h: i for i, h in enumerate(header)}
        body = np.array([[float(r[cols["t"]]), float(r[cols["D"]]), float(r[cols["F"]])]
                         for r in rows[1:] if r and r[0]])
        path = _write(out / f"{gz.name.removesuffix('.csv.gz')}.csv", *body.T)
        yield (f"MR damper {gz.name.removesuffix('_converted.csv.gz')}", path,
               "disp=cm,force=N", "MR damper, random voltage 0-2.25 V")
    if wanted("RC column Gill 1979"):
        rc = np.loadtxt(MEASURED / "rc_column_gill1979_peer_spd" / "experimental_data.csv",
                        delimiter=",", skiprows=1)
        yield ("RC column Gill 1979", _write(out / "rc_column.csv",
                                             np.arange(rc.shape[0], dtype=float),
                                             rc[:, 0], rc[:, 1]),
               "disp=m", "force is the normalised lateral load (read as kN)")
    for js in sorted((MEASURED / "steel_brace_cyclic_simcenter").glob("*.json")):
        if not wanted(f"brace {js.stem}"):
            continue
        test = json.loads(js.read_text())["test"]
        d, f = np.array(test["axialDef"], float), np.array(test["axialForce"], float)
        yield (f"brace {js.stem}", _write(out / f"{js.stem}.csv", np.arange(d.size, dtype=float),
                                          d, f), "disp=in,force=kip", "quasi-static, no time")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="benchmarks.diagnose_measured",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--out", type=Path, default=Path("out/measured"))
    parser.add_argument("--only", default=None, help="substring of the test names to run")
    parser.add_argument("--quick", action="store_true",
                        help="the RC column alone, into a temporary directory")
    parser.add_argument("--device", choices=sorted(DEVICES), default=None,
                        help="diagnose the device's records together (--same-device)")
    args = parser.parse_args(argv)
    require_shared(MEASURED, parser.prog)
    if args.quick:
        args.only = args.only or "RC column"
        args.out = Path(tempfile.mkdtemp(prefix="diagnose-measured-"))
    args.out.mkdir(parents=True, exist_ok=True)
    if args.device is not None:
        _device(args.device, args.out)
        return
    rows: list[tuple[str, ...]] = []
    for name, path, units, note in tests(args.out, args.only):
        out_json = path.with_suffix(".json")
        started, cpu_started = time.perf_counter(), time.process_time()
        rc = cli_main(["diagnose", str(path), "--units", units, "--json", str(out_json),
                       "--report", str(path.with_suffix("")), "--no-progress"])
        wall, cpu = time.perf_counter() - started, time.process_time() - cpu_started
        if rc != 0:
            rows.append((name, "error", "", "", "", "", f"{wall:.1f}", f"{cpu:.1f}"))
            continue
        doc = json.loads(out_json.read_text())
        v = doc["verdict"]
        winner = next((e for e in doc["effects"] + doc["pairs"] if e["name"] == v["effect"]), None)
        params = "" if winner is None else ", ".join(
            f"{k} {p['value']:.4g}±{(p['std'] or 0):.2g} {p['unit']}"
            for k, p in winner["params"].items())
        rows.append((name, f"{doc['record']['samples']}", doc["baseline"]["kind"], v["effect"],
                     f"{v['confidence']:.2f}",
                     f"{v['gap_before_pct']:.2f} → {v['gap_after_pct']:.2f} %", params,
                     f"{wall:.1f}", f"{cpu:.1f}", note))
    print("| test | samples | baseline | verdict | confidence | withheld gap | parameters | "
          "wall s | CPU s | note |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(r) + " |")


def _device(device: str, out: Path) -> None:
    """``diagnose --same-device`` on the device's records; the device summary is printed."""
    names = DEVICES[device]
    found = {name: (path, units) for name, path, units, _note in tests(out, "BRFD")
             if name in names}
    missing = [n for n in names if n not in found]
    if missing:
        raise SystemExit(f"benchmarks.diagnose_measured: no record {', '.join(missing)}")
    units = {u for _p, u in found.values()}
    assert len(units) == 1
    out_json = out / f"device-{device}.json"
    started, cpu_started = time.perf_counter(), time.process_time()
    rc = cli_main(["diagnose", *(str(found[n][0]) for n in names), "--same-device",
                   "--units", units.pop(), "--json", str(out_json),
                   "--report", str(out / f"device-{device}"), "--no-progress"])
    print(f"exit {rc}; wall {time.perf_counter() - started:.1f} s, CPU "
          f"{time.process_time() - cpu_started:.1f} s")


if __name__ == "__main__":
    main()
