"""Make real run directories for the report/runs/metrics tests: a real bridge, a real client."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from protocol import Action
from tests.support.bridge import RunningBridge

DT = 0.01

LAB_TOML = """
[bridge]
run_name = "{name}"
[telemetry]
monitor_window = 64
warn_tracking_error = 5.0
{telemetry}
[[sites]]
name = "spring"
port = 0
[sites.controller]
model = "bilinear"
params = {{ k0 = 10.0, fy = 8.0, alpha = 0.05 }}
"""


def drive(link: GenericClientLink, steps: int, *, amplitude: float = 2.0) -> None:
    """A growing sine (0.5 Hz) past yield: steps × (trial, getDisp, getForce, commit)."""
    for i in range(1, steps + 1):
        t = i * DT
        link.set_trial((amplitude * t * math.sin(math.pi * t),), time=t)
        link.request(Action.GET_DISP)
        link.force()
        link.commit()


def record_run(
    root: Path,
    steps: int = 300,
    *,
    name: str = "test",
    telemetry: str = "",
    hold_at_end: bool = True,
    during: Callable[[BridgeThread], Any] | None = None,
) -> tuple[Path, Any]:
    """One session of ``steps`` committed steps on a bilinear spring, then (optionally) a
    non-finite trial that puts the site in HOLD. ``during(bridge)`` runs before the bridge
    stops (e.g. to scrape /metrics); returns (run directory, what ``during`` returned)."""
    toml = LAB_TOML.format(name=name, telemetry=telemetry)
    seen = None
    with RunningBridge(toml, root) as bridge:
        with GenericClientLink("127.0.0.1", bridge.ports["spring"], 1, data_size=1) as link:
            link.matrix(Action.GET_INITIAL_STIFF)
            drive(link, steps)
            if hold_at_end:
                link.set_trial((math.nan,), time=(steps + 1) * DT)
                link.force()
        # the session-close event lands when the bridge reads the DIE
        deadline = time.monotonic() + 10
        while not any(json.loads(line).get("event") == "session-close"
                      for line in (bridge.run_dir / "record.jsonl").read_text().splitlines()
                      if '"kind":"event"' in line):
            assert time.monotonic() < deadline, "the bridge never closed the session"
            time.sleep(0.01)
        # the listeners after the recorder (metrics, taps) get the event in the same loop
        # callback: a round trip through the loop waits for them (a loaded machine can switch
        # threads between the record's write and the metrics' count)
        bridge.call(lambda: None)
        if during is not None:
            seen = during(bridge)
        run_dir = bridge.run_dir
    return run_dir, seen


RIG_SITE_TOML = """
[[sites]]
name = "rig"
port = 0
[sites.controller]
kind = "rig"
file = "{rig}"
ramp_time = {dt}
stiffness = 10.0
"""

NOISY_RIG = """
name = "noisy-rig"
seed = 5
substep_rate = 1000.0
settle_time = 0.0
default_ramp_time = {dt}
[specimen]
kind = "bilinear"
params = {{ k0 = 10.0, fy = 8.0, alpha = 0.05 }}
[sensors.lvdt]
noise_std = 0.02
"""
"""A simulated lab whose LVDT reads the piston with noise: measured displacement != command."""


def rig_site(root: Path) -> str:
    """The TOML of a site ``rig`` served by :data:`NOISY_RIG` (written under ``root``)."""
    rig = root / "rig.toml"
    rig.write_text(NOISY_RIG.format(dt=DT))
    return RIG_SITE_TOML.format(rig=rig, dt=DT)


def record_sessions(root: Path, toml: str, sessions: list[tuple[str, int]]) -> Path:
    """One bridge; one integrator session per (site, steps), in order, each closed before the
    next (a site takes its next client only then); returns the run directory."""
    with RunningBridge(toml, root) as bridge:
        for n, (site, steps) in enumerate(sessions, 1):
            with GenericClientLink("127.0.0.1", bridge.ports[site], 1, data_size=1) as link:
                drive(link, steps)
            deadline = time.monotonic() + 10
            while sum(r.get("event") == "session-close" for r in raw_lines(bridge.run_dir)) < n:
                assert time.monotonic() < deadline, "the bridge never closed the session"
                time.sleep(0.01)
        return bridge.run_dir


def raw_lines(run_dir: Path) -> list[dict[str, Any]]:
    """Every complete line of record.jsonl, decoded independently of fresco_bridge.record:
    format 2 (docs/run-record.md "The record format") filled in here by its written rules — a
    missing ``seq`` is the line's position, missing ``site``/``session`` are the previous line's, a
    missing value of a trial/daq/commit/monitor line is that of the previous line of its kind, site
    and session, a missing ``ctrl`` equals the trial — format 3's step lines unfolded into the
    monitor, trial, daq and commit lines they stand for, and format 4's monitors lines into their
    monitor lines."""
    text = (run_dir / "record.jsonl").read_text()
    out: list[dict[str, Any]] = []
    seen: dict[tuple[str, int, str], dict[str, Any]] = {}
    for line in text.split("\n")[:-1]:
        rec = json.loads(line)
        if "seq" not in rec:
            where = out[-1] if out else {}
            rec = {"seq": len(out) + 1, "site": where.get("site"),
                   "session": where.get("session"), **rec}
            if rec["kind"] == "step":
                out += unfold_step(rec, seen)
                continue
            if rec["kind"] == "monitors":
                out += unfold_monitors(rec, seen)
                continue
            if rec["kind"] not in ("event", "update"):  # complete lines
                had = "ctrl" in rec
                rec = {**seen.get((rec["site"], rec["session"], rec["kind"]), {}), **rec}
                if rec["kind"] == "trial" and not had:
                    rec["ctrl"] = rec["trial"]
        seen[(rec["site"], rec["session"], rec["kind"])] = rec
        out.append(rec)
    return out


def unfold_step(rec: dict[str, Any], seen: dict[tuple[str, int, str], dict[str, Any]]
                ) -> list[dict[str, Any]]:
    """A step line: [the monitor line of the step before: 5 values, 3 with the FEI pair as
    before, or 0 for all as before], a trial and a daq line per entry of
    ``it`` (0: all as before; else [trial, disp, force(, ctrl)], 0 for an unchanged vector),
    the commit line. ``seq`` follows on from the step line's position."""
    site, session, seq, step = rec["site"], rec["session"], rec["seq"], rec["step"]
    common = {"t": rec["t"], "site": site, "session": session}
    out: list[dict[str, Any]] = []
    if "mon" in rec:
        names = ("err", "ti", "nrms", "fei_amp", "fei_delay")
        values = rec["mon"]
        if values == 0:
            values = [seen[(site, session, "monitor")][k] for k in names]
        elif len(values) == 3:
            values = [*values, *(seen[(site, session, "monitor")][k] for k in names[3:])]
        out.append({**common, "kind": "monitor", "step": step - 1,
                    **dict(zip(names, values, strict=True))})
    trial = seen[(site, session, "trial")]
    daq = seen[(site, session, "daq")]
    for it in rec["it"]:
        if it != 0:
            new_trial = trial["trial"] if it[0] == 0 else it[0]
            trial = {**common, "kind": "trial", "trial": new_trial,
                     "ctrl": it[3] if len(it) == 4 else new_trial}
            daq = {**common, "kind": "daq", "disp": daq["disp"] if it[1] == 0 else it[1],
                   "force": daq["force"] if it[2] == 0 else it[2]}
        trial = {**trial, **common, "step": step - 1, "time": rec["time"]}
        daq = {**daq, **common, "step": step - 1}
        out += [trial, daq]
    out.append({**common, "kind": "commit", "step": step, "time": rec["time"]})
    for n, line in enumerate(out):
        line["seq"] = seq + n
        seen[(site, session, line["kind"])] = line
    return out


def unfold_monitors(rec: dict[str, Any], seen: dict[tuple[str, int, str], dict[str, Any]]
                    ) -> list[dict[str, Any]]:
    """A monitors line: the monitor lines of steps ``step``, ``step + 1``…, one per entry of
    ``v`` (5 values, 3 with the FEI pair as before, or 0 for all as before). ``seq`` follows on
    from the line's position."""
    site, session = rec["site"], rec["session"]
    names = ("err", "ti", "nrms", "fei_amp", "fei_delay")
    out: list[dict[str, Any]] = []
    for n, values in enumerate(rec["v"]):
        before = seen.get((site, session, "monitor"))
        if values == 0:
            assert before is not None
            values = [before[k] for k in names]
        elif len(values) == 3:
            assert before is not None
            values = [*values, before["fei_amp"], before["fei_delay"]]
        line = {"seq": rec["seq"] + n, "t": rec["t"], "site": site, "session": session,
                "kind": "monitor", "step": rec["step"] + n, **dict(zip(names, values, strict=True))}
        seen[(site, session, "monitor")] = line
        out.append(line)
    return out
