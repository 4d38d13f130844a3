"""``../shared`` for the benchmarks that read its measured data (the product never does)."""

from __future__ import annotations

import sys
from pathlib import Path

SHARED = Path(__file__).resolve().parents[2] / "shared"
"""``../shared`` beside the repository: specs, captures, measured data."""
MEASURED = SHARED / "data" / "measured"


def require_shared(path: Path, benchmark: str) -> Path:
    """``path``, or exit with a message naming what is missing (exit status 2)."""
    if not path.exists():
        print(f"{benchmark}: needs {path} from ../shared (not found; the benchmark reads "
              "measured data that only ../shared holds)", file=sys.stderr)
        raise SystemExit(2)
    return path
