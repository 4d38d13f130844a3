"""``study paper`` on a real Dask ``LocalCluster`` (small): same numbers as in process."""

from __future__ import annotations

import json
from pathlib import Path

from fresco_bridge.cli import main


def test_study_through_a_local_dask_cluster(tmp_path: Path) -> None:
    from distributed import LocalCluster

    common = ["study", "paper", "--specimen", "menegotto-pinto", "--steps", "100", "--seed", "2",
              "--cases", "conventional_calibrated", "--no-plots"]  # fmt: skip
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        assert main([*common, "--scheduler", cluster.scheduler_address,
                     "-o", str(tmp_path / "dask")]) == 0  # fmt: skip
    assert main([*common, "--workers", "1", "-o", str(tmp_path / "local")]) == 0
    dask_doc = json.loads((tmp_path / "dask" / "summary.json").read_text())
    local_doc = json.loads((tmp_path / "local" / "summary.json").read_text())
    assert dask_doc == local_doc
