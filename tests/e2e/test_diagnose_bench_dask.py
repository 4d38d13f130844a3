"""``diagnose-bench`` on a real Dask ``LocalCluster``: records generated and diagnosed on its
workers, results back in order, the summary consistent with the records."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fresco_bridge.cli import main


def test_a_tiny_bench_runs_on_a_local_cluster(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    from distributed import LocalCluster

    out = tmp_path / "bench.json"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster:
        rc = main(["diagnose-bench", "--n", "2", "--seed", "3", "--steps", "400",
                   "--scheduler", cluster.scheduler_address, "--json", str(out),
                   "--no-progress"])
    text = capsys.readouterr().out
    assert rc == 0
    doc = json.loads(out.read_text())
    rows = doc["records"]
    assert [r["index"] for r in rows] == [0, 1]
    assert [r["effect"] for r in rows] == ["actuator_delay", "actuator_amplitude"]
    confusion = doc["summary"]["confusion"]
    assert sum(sum(row.values()) for row in confusion.values()) == 2
    correct = sum(r["predicted"] == r["effect"] for r in rows)
    assert doc["summary"]["top1_pct"] == pytest.approx(50.0 * correct)
    assert "confusion (rows: true effect, columns: verdict)" in text


def test_an_independent_bench_runs_on_a_local_cluster(tmp_path: Path) -> None:
    from distributed import LocalCluster

    from benchmarks.diagnosis.independent import case_label

    out = tmp_path / "bench.json"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster:
        rc = main(["diagnose-bench", "--independent", "--n", "2", "--seed", "5", "--steps",
                   "300", "--scheduler", cluster.scheduler_address, "--json", str(out),
                   "--no-progress"])
    assert rc == 0
    rows = json.loads(out.read_text())["records"]
    assert [r["effect"] for r in rows] == [case_label(5, 0), case_label(5, 1)]
