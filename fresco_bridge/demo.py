"""``fresco-bridge demo --simple``: the source paper's two-story frame, end to end, in one process.

The bridge runs on its own event loop thread with an in-process simulated bending damper; our
explicit-Newmark integrator plays OpenSees and drives it over the genericClient protocol on
loopback, exactly as a separate FE process would. Embedded defaults only: no broker, no
hardware, no files from outside the package. An ideal specimen and no twin: the plumbing alone
(the default demo, the paper's whole story, is ``demo_story``).
"""

from __future__ import annotations

import contextlib
import json
import logging
import signal
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from types import FrameType
from typing import Any

import numpy as np

from .config import LabConfig, parse_config
from .daemon import BridgeThread
from .exit_codes import Interrupted
from .integrator import (
    DEMO_DAMPER,
    DEMO_DT,
    DEMO_FRAME_STORY_STIFFNESS,
    GroundMotion,
    demo_frame_integrator,
    demo_site_coupling,
    kanai_tajimi,
    paper_two_story_frame,
    read_ground_motion,
    run_coupled,
)
from .integrator.link import GenericClientLink
from .numbers import fmt
from .progress import ProgressBar, command_name
from .record import export_csv
from .runs import mark_interrupted

BRIDGE_LOG = "bridge.log"
"""The demo's bridge's log lines, in its run directory (not between the story's lines)."""


class _RunLog(logging.Handler):
    """Every log line of one bridge run into its ``bridge.log``; the lines logged before its
    run directory exists (the bridge's start) are held and written first."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.setFormatter(logging.Formatter("%(asctime)s %(levelname)-7s %(name)s: %(message)s"))
        self._held: list[logging.LogRecord] = []
        self._file: logging.FileHandler | None = None

    def open(self, path: Path) -> None:
        self._file = logging.FileHandler(path, encoding="utf-8")
        self._file.setFormatter(self.formatter)
        for record in self._held:
            self._file.emit(record)
        self._held.clear()

    def emit(self, record: logging.LogRecord) -> None:
        if self._file is None:
            self._held.append(record)
        else:
            self._file.emit(record)

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
        super().close()


def _terminal_handlers() -> list[logging.Handler]:
    return [h for h in logging.getLogger().handlers
            if isinstance(h, logging.StreamHandler) and not isinstance(h, logging.FileHandler)]


@contextlib.contextmanager
def story_terminal() -> Iterator[None]:
    """The demo's terminal is its story: the log lines below warnings (a bridge's session
    lines, protocol sizes, a font cache) stay off it for the whole demo (each bridge's go to
    its ``bridge.log``, ``bridge_act``), and after Ctrl-C none at all (what the closing
    bridges log then, a HOLD of the session cut short, is in ``bridge.log``): the one
    ``interrupted:`` line follows. In the main thread (it sets the SIGINT handler)."""
    handlers = [(h, h.level) for h in _terminal_handlers()]
    for handler, level in handlers:
        handler.setLevel(max(level, logging.WARNING))

    def interrupted(signum: int, frame: FrameType | None) -> None:
        for handler, _ in handlers:
            handler.setLevel(logging.CRITICAL + 1)
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, interrupted)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        for handler, level in handlers:
            handler.setLevel(level)


@contextlib.contextmanager
def bridge_act(cfg: LabConfig, text: str, runs: Path, act: str) -> Iterator[BridgeThread]:
    """One act's bridge, its log in its run directory's ``bridge.log``. Ctrl-C during the act:
    the bridge closes quietly, the run is recorded as interrupted and ``Interrupted`` says
    so in one line."""
    root = logging.getLogger()
    run_log, level = _RunLog(), root.level
    root.addHandler(run_log)
    root.setLevel(min(level, logging.INFO) if level != logging.NOTSET else logging.INFO)
    thread = BridgeThread(cfg, text, run_dir=runs)
    try:
        with thread as bridge:
            run_log.open(bridge.run_dir / BRIDGE_LOG)
            yield bridge
            bridge.drain()  # the act's clients have sent DIE: let their sessions end
    except KeyboardInterrupt as exc:  # in the act, or while its bridge was starting
        if isinstance(exc, Interrupted):
            raise
        thread.stop()
        record = thread.bridge.record
        if record is None:
            raise Interrupted(f"fresco-bridge demo stopped by Ctrl-C in {act}, before its "
                              "run was recorded") from None
        run = record.directory
        mark_interrupted(run)
        raise Interrupted(
            f"fresco-bridge demo stopped by Ctrl-C in {act}; the run is recorded as "
            f"interrupted: {run} (its bridge's log: {run}/{BRIDGE_LOG}; next: "
            f"{command_name()} runs show {run})") from None
    finally:
        root.removeHandler(run_log)
        root.setLevel(level)
        run_log.close()


def telemetry_text(mqtt: str | None = None, mqtt_prefix: str = "fresco",
                   metrics_port: int | None = None) -> str:
    """The ``[telemetry]`` table of a demo config: empty unless ``mqtt`` (``HOST`` or
    ``HOST:PORT``) or ``metrics_port`` is given, as the embedded default needs no broker."""
    telemetry = ""
    if mqtt is not None:
        host, _, port = mqtt.partition(":")
        telemetry += f'mqtt_host = {json.dumps(host)}\nprefix = {json.dumps(mqtt_prefix)}\n'
        if port:
            if not port.isdigit():
                raise ValueError(f"--mqtt {mqtt!r}: the port after ':' must be a number")
            telemetry += f"mqtt_port = {int(port)}\n"
    if metrics_port is not None:
        telemetry += f"metrics_port = {int(metrics_port)}\n"
    return "\n[telemetry]\n" + telemetry if telemetry else ""


def demo_config_text(transport: str = "tcp", run_name: str = "demo", *,
                     mqtt: str | None = None, mqtt_prefix: str = "fresco",
                     metrics_port: int | None = None) -> str:
    """The ``--simple`` demo's lab config as TOML (it is also the run's config snapshot).

    Telemetry is off unless ``mqtt`` (``HOST`` or ``HOST:PORT``) or ``metrics_port`` is given:
    the embedded default needs no broker.
    """
    telemetry = telemetry_text(mqtt, mqtt_prefix, metrics_port)
    return f"""# fresco-bridge demo: source paper's two-story frame, damper in story 1 (mm, kN, s)
[bridge]
run_name = "{run_name}"

[[sites]]
name = "damper"
port = 0
transport = "{transport}"
dofs = 2
setup = "OneActuator"

[sites.controller]
kind = "sim"
model = "{DEMO_DAMPER['model']}"
params = {{ k0 = {DEMO_DAMPER['k0']!r}, fy = {DEMO_DAMPER['fy']!r}, \
alpha = {DEMO_DAMPER['alpha']!r} }}
{telemetry}"""


def run_demo(
    *,
    record: Path | None = None,
    pga: float = 3.0,
    duration: float = 20.0,
    seed: int = 1,
    runs: Path = Path("runs"),
    transport: str = "tcp",
    mqtt: str | None = None,
    mqtt_prefix: str = "fresco",
    metrics_port: int | None = None,
) -> dict[str, Any]:
    """Run the demo; returns the summary (also written to the run directory)."""
    if record is not None:
        motion: GroundMotion = read_ground_motion(record).scaled_to_pga(pga)
    else:
        motion = kanai_tajimi(pga, duration=duration, dt=DEMO_DT, seed=seed)
    text = demo_config_text(transport, mqtt=mqtt, mqtt_prefix=mqtt_prefix,
                            metrics_port=metrics_port)
    cfg = parse_config(text, "<demo config>")
    print(f"fresco-bridge demo: two-story frame, damper in story 1 served by the bridge "
          f"({transport.upper()}), record {motion.name} scaled to PGA {pga:g} m/s²",
          file=sys.stderr)
    with bridge_act(cfg, text, runs, "the run") as bridge:
        port = bridge.ports["damper"]
        link = GenericClientLink("127.0.0.1", port, 2, transport=transport, timeout=10.0)
        coupling = demo_site_coupling(link)
        integ = demo_frame_integrator(coupling, motion)
        progress = ProgressBar("demo", integ.n_steps, rate_unit="steps")
        t0 = time.perf_counter()
        with link:
            response = run_coupled(integ, coupling, progress=progress)
        wall = time.perf_counter() - t0
        run_dir = bridge.run_dir
    n_rows = export_csv(run_dir, run_dir / "steps.csv")
    summary = _summary(response, motion, wall, integ.n_steps, run_dir, n_rows)
    (run_dir / "summary.json").write_text(json.dumps(summary, indent=2), encoding="utf-8")
    _plot(response, run_dir / "hysteresis.png")
    from .report.html import write_report  # matplotlib is loaded by _plot anyway

    write_report(run_dir)
    _print_summary(summary)
    return summary


def _summary(resp: Any, motion: GroundMotion, wall: float, n_steps: int, run_dir: Path,
             n_rows: int) -> dict[str, Any]:
    drift = resp.drift
    fy = float(DEMO_DAMPER["fy"])
    dy = fy / float(DEMO_DAMPER["k0"])
    force = resp.experimental_force[:, 0]
    return {
        "run_dir": str(run_dir),
        "record": motion.name,
        "pga_m_s2": round(motion.pga_m_s2, 9),
        "steps": n_steps,
        "dt_s": DEMO_DT,
        "wall_s": round(wall, 3),
        "ms_per_step": round(1000 * wall / max(n_steps, 1), 4),
        "frame_story_stiffness_kN_mm": DEMO_FRAME_STORY_STIFFNESS,
        "damper": dict(DEMO_DAMPER),
        "periods_s_with_damper": [round(float(x), 4) for x in paper_two_story_frame().modes(
            np.array([float(DEMO_DAMPER["k0"]), 0.0])).period],
        "peak_story_drift_mm": [round(float(np.max(np.abs(drift[:, i]))), 4)
                                for i in range(drift.shape[1])],
        "peak_roof_disp_mm": round(float(np.max(np.abs(resp.displacement[:, -1]))), 4),
        "peak_damper_force_kN": [round(float(force.max()), 4), round(float(force.min()), 4)],
        "damper_yield_disp_mm": dy,
        "damper_ductility": round(float(np.max(np.abs(drift[:, 0]))) / dy, 2),
        "committed_steps_in_record": n_rows,
        "files": ["config.toml", "run.json", "record.jsonl", "steps.csv", "summary.json",
                  "hysteresis.png", "report.html"],
    }


def _plot(resp: Any, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    ax1.plot(resp.drift[:, 0], resp.experimental_force[:, 0], lw=0.8)
    ax1.set_xlabel("story-1 drift (mm)")
    ax1.set_ylabel("damper force (kN)")
    ax1.set_title("Damper hysteresis (measured through the bridge)")
    ax1.grid(alpha=0.3)
    ax2.plot(resp.time, resp.displacement[:, 0], lw=0.8, label="floor 1")
    ax2.plot(resp.time, resp.displacement[:, 1], lw=0.8, label="floor 2")
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("displacement relative to ground (mm)")
    ax2.legend()
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _print_summary(s: dict[str, Any]) -> None:
    drift = " / ".join(fmt(d) for d in s["peak_story_drift_mm"])
    periods = " / ".join(fmt(x) for x in s["periods_s_with_damper"])
    f_max, f_min = s["peak_damper_force_kN"]
    print(
        f"\nrun directory     {s['run_dir']}\n"
        f"steps             {s['steps']} x {fmt(s['dt_s'])} s in {fmt(s['wall_s'], 's', 3)} "
        f"({fmt(s['ms_per_step'], 'ms', 3)}/step through the bridge)\n"
        f"periods           {periods} s\n"
        f"peak story drift  {drift} mm   roof {fmt(s['peak_roof_disp_mm'], 'mm')}\n"
        f"damper force      max {fmt(f_max)} / min {fmt(f_min, 'kN')}, ductility "
        f"{fmt(s['damper_ductility'], digits=3)} (yield at "
        f"{fmt(s['damper_yield_disp_mm'], 'mm', 3)})\n"
        f"record            {s['committed_steps_in_record']} committed steps (the first is "
        f"the initial state at t = 0) -> steps.csv, "
        f"hysteresis.png, summary.json, report.html",
        file=sys.stderr,
    )
