"""Run every benchmark in this package: ``python -m benchmarks.run_all``."""

from __future__ import annotations

from collections.abc import Callable

from benchmarks import (
    bench_modbus_adapter,
    bench_online_ann,
    bench_online_improved,
    bench_opensees_bridge,
    bench_safety,
    bench_telemetry,
)

BENCHMARKS: dict[str, Callable[[list[str] | None], None]] = {
    "opensees_bridge": bench_opensees_bridge.main,
    "modbus_adapter": bench_modbus_adapter.main,
    "safety": bench_safety.main,
    "telemetry": bench_telemetry.main,
    "online_improved": bench_online_improved.main,
    "online_ann": bench_online_ann.main,
}


def main() -> None:
    """Each benchmark prints its own table; see BENCHMARKS.md for the recorded results."""
    for name, bench in BENCHMARKS.items():
        print(f"=== {name} ===", flush=True)
        bench([])


if __name__ == "__main__":
    main()
