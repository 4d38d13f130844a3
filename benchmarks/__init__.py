"""Speed benchmarks (run with ``python -m benchmarks.run_all``); results go in BENCHMARKS.md."""
