"""Measured device records of ``../shared/data/measured`` as the CSV the tools read."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

from tests.support.paths import SHARED

BRFD = SHARED / "data" / "measured" / "rotary_friction_damper_BRFD"
"""The banded rotary friction damper: 1024 Hz, inches and kips (``--units in,kip``)."""


def brfd_csv(record: str, decimate: int, path: Path) -> Path:
    """``time,disp,force`` of the BRFD's dataset-3 ``record``, every ``decimate``-th sample."""
    doc = json.loads(gzip.decompress((BRFD / f"dataset-3_{record}.json.gz").read_bytes()))
    rows = np.array(doc["data"], dtype=np.float64)[::decimate, :3]
    np.savetxt(path, rows, fmt="%.17g", delimiter=",", header="time,disp,force", comments="")
    return path
