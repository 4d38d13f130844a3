"""The 60-second soak (issue 11): 32 sites, one paced client each, against a real
``fresco-bridge serve`` process. No timed assertion: latency is only reported (the 10-minute
figures are in BENCHMARKS.md); memory, file descriptors, correctness and the record are checked.
"""

from __future__ import annotations

from pathlib import Path

from benchmarks.bench_soak import soak
from fresco_bridge.record import read_record
from fresco_bridge.record.export import pair_commits


def test_a_60_second_soak_of_32_sites_leaks_nothing(tmp_path: Path) -> None:
    result, run_dir = soak(60.0, sites=32, rate=20.0, warmup=15.0, sample=1.0,
                           workdir=tmp_path)
    summary = result.summary()
    print(summary)
    assert result.errors == [] and result.wrong == 0 and result.steps > 0
    after, low, high = result.fds
    assert low == high == after, f"bridge fds changed after warm-up: {result.fds}"
    assert result.rss_growth <= 0.10, summary
    committed = pair_commits(read_record(run_dir))
    assert len(committed) == result.steps
    assert {s.site for s in committed} == {f"s{i:02d}" for i in range(32)}
