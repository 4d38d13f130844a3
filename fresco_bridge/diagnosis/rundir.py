"""A site's diagnosis kept in its run directory, where the run's report finds it.

``diagnose RUN --site S --report RUN/diagnosis-S`` by another name: the demo's last act and
``report RUN --diagnose S`` call it; ``fresco_bridge.report.diagnosis`` renders what it wrote.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from ..report.diagnosis import DIAGNOSIS_PREFIX, headline
from .interface_gap import interface_gap
from .load import load_record
from .outputs import write_report
from .verdict import Options, diagnose

__all__ = ["diagnose_into_run"]


def diagnose_into_run(run_dir: Path, site: str,
                      progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Diagnose ``site`` of ``run_dir`` with ``diagnose``'s defaults into
    ``RUN/diagnosis-<site>/``; returns the diagnosis' headline (verdict, magnitude, shrink).
    ``DiagnosisInputError`` for a record it cannot diagnose (e.g. too short)."""
    result = diagnose(load_record(run_dir, site=site), Options(), progress=progress)
    result = replace(result, interface_gap=interface_gap(run_dir, site))
    write_report(result, run_dir / f"{DIAGNOSIS_PREFIX}{site}")
    return headline(result.to_json())
