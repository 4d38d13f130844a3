"""A 60-second soak: 32 sites, one paced client each, against a real ``fresco-bridge serve``
process, run as a user runs it (``python -m benchmarks.bench_soak``). No timed assertion:
latency is only reported (the 10-minute figures are in BENCHMARKS.md, "Fuzz and soak");
memory, file descriptors, correctness and the record are checked.
"""

from __future__ import annotations

import json
from pathlib import Path

from fresco_bridge.record import read_record
from fresco_bridge.record.export import pair_commits
from tests.support.benchmark import run_benchmark


def test_a_60_second_soak_of_32_sites_leaks_nothing(tmp_path: Path) -> None:
    out = tmp_path / "summary.json"
    run_benchmark("bench_soak", "--minutes", "1", "--sites", "32", "--rate", "20",
                  "--warmup", "15", "--sample", "1", "--workdir", str(tmp_path),
                  "--json", str(out), deadline=300.0)  # fmt: skip
    summary = json.loads(out.read_text(encoding="utf-8"))
    print(json.dumps(summary, indent=1))
    assert summary["errors"] == [] and summary["wrong_forces"] == 0 and summary["steps"] > 0
    after, low, high = summary["fds_after_warmup_min_max"]
    assert low == high == after, f"bridge fds changed after warm-up: {(after, low, high)}"
    assert summary["rss_growth_pct"] <= 10.0, summary
    committed = pair_commits(read_record(Path(summary["run_dir"])))
    assert len(committed) == summary["steps"]
    assert {s.site for s in committed} == {f"s{i:02d}" for i in range(32)}
