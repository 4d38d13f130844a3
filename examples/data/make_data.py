"""Rebuild this folder's measured histories from their archived originals (not needed to use them).

    python examples/data/make_data.py [--shared ../shared]

Reads the banded rotary friction damper (BRFD) records of ``<shared>/data/measured/
rotary_friction_damper_BRFD`` (JSON, 1024 Hz, inches and kips; the upstream files gzip-compressed
unchanged) and writes ``brfd_*.csv``: ``time,disp,force`` in s, mm and kN (the bridge's units, so
no ``--units`` is needed), every 16th sample (64 Hz), the displacement to 0.1 um and the force to
0.1 N (far below the sensors' noise). Nothing else is changed: no filtering, no offset removal.
The ground motion ``RSN960_NORTHR_LOS270.AT2`` is a byte copy of
``<shared>/data/ground_motions/RSN960_NORTHR_LOS270.AT2`` and is copied, not rebuilt, here.
``SHA256SUMS`` lists what this writes; the README says where each file comes from.
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import json
import shutil
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
MM_PER_IN = 25.4
KN_PER_KIP = 4.4482216152605
DECIMATE = 16
FILES = {
    # output: (BRFD record, rows kept after decimation; None = all)
    "brfd_imperial_valley_dbe.csv": ("ImperialValleyDBE", None),
    "brfd_imperial_valley_mce.csv": ("ImperialValleyMCE", None),
    # the offline database: the first 19.5 s (almost 5 cycles) of the 0.25 Hz, 1 in sine, the
    # span benchmarks/updater_measured.py uses (2500 steps at 128 Hz)
    "brfd_sine_0.25hz.csv": ("0.25Hz30lbtension1amplitude", 1250),
}
RECORD = "RSN960_NORTHR_LOS270.AT2"


def convert(source: Path, keep: int | None) -> str:
    """One record as the CSV text written here."""
    data = np.array(json.loads(gzip.decompress(source.read_bytes()))["data"], dtype=np.float64)
    rows = data[::DECIMATE, :3][:keep]
    lines = ["time,disp,force"]
    lines += [f"{t:.6f},{d * MM_PER_IN:.4f},{f * KN_PER_KIP:.4f}" for t, d, f in rows]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--shared", type=Path, default=HERE.parents[2] / "shared")
    args = parser.parse_args()
    brfd = args.shared / "data" / "measured" / "rotary_friction_damper_BRFD"
    if not brfd.is_dir():
        raise SystemExit(f"make_data: {brfd} not found (pass --shared)")
    for name, (record, keep) in FILES.items():
        (HERE / name).write_text(convert(brfd / f"dataset-3_{record}.json.gz", keep),
                                 encoding="utf-8")
    shutil.copyfile(args.shared / "data" / "ground_motions" / RECORD, HERE / RECORD)
    names = sorted([*FILES, RECORD])
    (HERE / "SHA256SUMS").write_text("".join(
        f"{hashlib.sha256((HERE / n).read_bytes()).hexdigest()}  {n}\n" for n in names),
        encoding="utf-8")
    total = sum((HERE / n).stat().st_size for n in names)
    print(f"wrote {len(names)} files, {total:,} bytes, in {HERE}")


if __name__ == "__main__":
    main()
