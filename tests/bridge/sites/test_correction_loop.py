"""The correction loop against real controllers: the in-process ``rig`` with a compliant frame,
a pin gap and servo undershoot, and the Modbus adapter over loopback to ``sim-actuator serve``'s
server, reading the external channel."""

from __future__ import annotations

import asyncio
import contextlib
import select
import subprocess
import sys
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any, TypeVar

import pytest

from fresco_bridge.controls.base import Controller, ControllerError
from fresco_bridge.controls.modbus import ModbusController, ModbusControllerConfig
from fresco_bridge.controls.mts import MtsController, MtsControllerConfig
from fresco_bridge.controls.rig import RigController, RigControllerConfig
from fresco_bridge.safety import ControlPointLimits, CorrectionConfig, Limiter, SiteState
from fresco_bridge.sites.correction_loop import CorrectionLoop, LimitedPath, StepCorrection
from sim_actuator.config import RigConfig, build_rig, parse_rig_config
from sim_actuator.servers.controller import RigController as ServedRig
from sim_actuator.servers.modbus import ModbusRigServer
from sim_actuator.servers.mts_stub import MtsStubServer
from tests.support.net import free_ports

T = TypeVar("T")

ELASTIC = {"kind": "elastic", "params": {"k": 8.0}}


def run(factory: Callable[[], Awaitable[T]]) -> T:
    async def bounded() -> T:
        return await asyncio.wait_for(factory(), 60)

    return asyncio.run(bounded())


def rig_description(**effects: Any) -> dict[str, Any]:
    actuator = effects.pop("actuator", {})
    return {"name": "test", "specimen": ELASTIC, "actuator": actuator, "effects": effects,
            "default_ramp_time": 0.05, "settle_time": 0.01}


def toml(table: dict[str, Any], prefix: str = "") -> str:
    """A rig description as TOML (scalars first, then sub-tables; enough for these rigs)."""
    lines = [f"{k} = {v!r}" if not isinstance(v, str) else f'{k} = "{v}"'
             for k, v in table.items() if not isinstance(v, dict)]
    for k, v in table.items():
        if isinstance(v, dict):
            lines += [f"[{prefix}{k}]", toml(v, f"{prefix}{k}.")]
    return "\n".join(lines)


def rig(tmp_path: Path, *, external: bool = True, **effects: Any) -> RigController:
    file = tmp_path / "rig.toml"
    file.write_text(toml(rig_description(**effects)), encoding="utf-8")
    return RigController(RigControllerConfig(file=file,
                                             external="specimen" if external else None))


def loop(controller: Controller, *, limits: list[ControlPointLimits] | None = None,
         external: bool = True, **correction: Any) -> tuple[CorrectionLoop, LimitedPath]:
    options = {"tolerance": 0.01, "max_correction": 2.0, **correction}
    if external:
        options["measured"] = "external"
    config = CorrectionConfig(**options)
    path = LimitedPath(controller, Limiter(limits or [], controller.n_actuators))
    settings = config.to_settings(controller.n_actuators)
    return CorrectionLoop(path, settings, controller,
                          external=config.measured == "external"), path


def drive(correction: CorrectionLoop, targets: list[float]) -> list[StepCorrection]:
    async def steps() -> list[StepCorrection]:
        done = []
        for t in targets:
            step = await correction.run((t,))
            done.append(step)
            if step.verdict.hold:
                break
        return done

    return run(steps)


TARGETS = [2.0, 5.0, 8.0, 3.0, -4.0, -9.0, 1.0]


def test_the_loop_closes_a_compliant_frame(tmp_path: Path) -> None:
    # frame 48 kN/mm behind an 8 kN/mm specimen: the specimen sits 14.5 % short of the command
    controller = rig(tmp_path, frame={"stiffness": 48.0})
    uncorrected = [controller.rig.execute(t).specimen_displacement for t in TARGETS]
    assert max(abs(u - t) for u, t in zip(uncorrected, TARGETS, strict=True)) > 1.0
    correction, path = loop(rig(tmp_path, frame={"stiffness": 48.0}))
    steps = drive(correction, TARGETS)
    assert [s.verdict.outcome for s in steps] == ["converged"] * len(TARGETS)
    for step, target in zip(steps, TARGETS, strict=True):
        assert step.residual <= 0.01
        assert step.daq is not None and step.daq.external is not None
        assert abs(step.daq.external[0] - target) <= 0.01
        assert 1 <= step.corrections <= 3
        assert step.iterations[0].command == (target,)
    assert path.state == SiteState.RUNNING
    # the record's view: every iteration's command and measurement
    record = steps[1].as_record()
    assert record["target"] == [5.0] and record["outcome"] == "converged"
    assert len(record["iterations"]) == steps[1].corrections + 1  # type: ignore[arg-type]


def test_the_loop_closes_a_pin_gap(tmp_path: Path) -> None:
    correction, _ = loop(rig(tmp_path, backlash={"gap": 0.3}))
    steps = drive(correction, TARGETS)
    assert [s.verdict.outcome for s in steps] == ["converged"] * len(TARGETS)
    assert all(s.residual <= 0.01 for s in steps)
    # a reversal crosses the gap: that step needed a correction
    assert steps[4].corrections >= 1


def test_servo_undershoot_is_seen_by_the_daq_channel_itself(tmp_path: Path) -> None:
    controller = rig(tmp_path, external=False, actuator={"undershoot": 0.2})
    correction, _ = loop(controller, external=False)
    steps = drive(correction, TARGETS)
    assert [s.verdict.outcome for s in steps] == ["converged"] * len(TARGETS)
    assert all(s.corrections == 1 for s in steps)


def test_a_correction_beyond_max_correction_holds_and_nothing_beyond_is_sent(
        tmp_path: Path) -> None:
    # a soft frame (8 kN/mm, as stiff as the specimen): the specimen gets half the command
    controller = rig(tmp_path, frame={"stiffness": 8.0})
    correction, path = loop(controller, max_correction=1.5)
    step = drive(correction, [2.0, 3.0])[-1]
    # 2 → measured 1, so 3 (1 off); → 1.5, so 3.5 (1.5 off); → 1.75, so 3.75: beyond 1.5
    assert step.target == (2.0,) and step.verdict.outcome == "beyond-max-correction"
    assert step.verdict.hold and step.verdict.value == pytest.approx(1.75, abs=1e-6)
    assert path.sent == [(2.0,), pytest.approx((3.0,)), pytest.approx((3.5,))]
    assert path.state == SiteState.HOLD and "max_correction 1.5 mm" in path.reason
    # after HOLD nothing more is forwarded
    sent = len(path.sent)
    after = run(lambda: correction.run((1.0,)))
    assert after.verdict.outcome == "refused" and len(path.sent) == sent


def test_non_convergence_holds_by_default(tmp_path: Path) -> None:
    correction, path = loop(rig(tmp_path, frame={"stiffness": 8.0}), gain=0.3,
                            max_iterations=2, max_correction=10.0)
    step = drive(correction, [4.0])[0]
    assert step.verdict.outcome == "not-converged" and step.verdict.hold
    assert step.corrections == 2 and path.state == SiteState.HOLD
    assert "after the last allowed correction" in path.reason


def test_non_convergence_accepted_with_an_event(tmp_path: Path) -> None:
    correction, path = loop(rig(tmp_path, frame={"stiffness": 8.0}), gain=0.3,
                            max_iterations=2, max_correction=10.0, policy="accept-with-event")
    steps = drive(correction, [4.0, 6.0])
    assert [s.verdict.outcome for s in steps] == ["not-converged"] * 2
    assert all(s.verdict.event and not s.verdict.hold for s in steps)
    assert all(s.warn for s in steps)  # 2 of 2 iterations: more than half
    assert path.state == SiteState.RUNNING
    assert steps[-1].daq is not None and steps[-1].daq.force[0] > 0.0


def test_a_limit_clamps_or_rejects_a_correction(tmp_path: Path) -> None:
    clamp = ControlPointLimits(0, disp_max=5.2, policy="clamp")
    correction, path = loop(rig(tmp_path, frame={"stiffness": 8.0}), limits=[clamp],
                            max_correction=10.0, max_iterations=3,
                            policy="accept-with-event")
    step = drive(correction, [5.0])[0]
    assert max(c[0] for c in path.sent) == 5.2  # every correction clamped at the limit
    assert step.verdict.outcome == "not-converged"
    reject = ControlPointLimits(0, disp_max=5.2)
    correction, path = loop(rig(tmp_path, frame={"stiffness": 8.0}), limits=[reject],
                            max_correction=10.0)
    step = drive(correction, [5.0])[0]
    assert step.verdict.outcome == "refused" and path.state == SiteState.HOLD
    assert path.sent == [(5.0,)] and "absolute limit 5.2 mm" in path.reason


def test_measured_external_needs_an_external_channel(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no external channel configured"):
        loop(rig(tmp_path, external=False))


def compliant() -> RigConfig:
    return parse_rig_config(rig_description(frame={"stiffness": 48.0}))


@contextlib.asynccontextmanager
async def modbus(config: RigConfig, **adapter: Any) -> AsyncIterator[ModbusController]:
    served = ServedRig(build_rig(config))
    server = ModbusRigServer(served, host="127.0.0.1", port=0)
    _, port = await server.start()
    served.start_heartbeat(50.0)
    ctl = ModbusController(ModbusControllerConfig(
        kind="modbus", port=port, request_timeout=2.0, ramp_time=0.05, **adapter))
    await ctl.connect()
    try:
        yield ctl
    finally:
        await ctl.close()
        await server.stop()
        await served.close()


def test_modbus_over_loopback_with_the_external_register() -> None:
    async def scenario() -> list[StepCorrection]:
        async with modbus(compliant(), external_register=24) as ctl:
            correction, _ = loop(ctl)
            return [await correction.run((t,)) for t in TARGETS[:4]]

    steps = run(scenario)
    assert [s.verdict.outcome for s in steps] == ["converged"] * 4
    assert all(s.residual <= 0.01 and 1 <= s.corrections <= 3 for s in steps)
    # float32 on the wire: the specimen is where the in-process rig puts it, to float32
    assert all(s.daq is not None and s.daq.external is not None for s in steps)


def test_modbus_daq_channel_cannot_see_the_frame() -> None:
    async def scenario() -> StepCorrection:
        async with modbus(compliant()) as ctl:
            correction, _ = loop(ctl, external=False)
            return await correction.run((5.0,))

    step = run(scenario)
    assert step.verdict.outcome == "converged" and step.corrections == 0
    assert step.daq is not None and step.daq.external is None


def test_mts_over_loopback_with_the_external_field() -> None:
    async def scenario() -> list[StepCorrection]:
        served = ServedRig(build_rig(compliant()))
        server = MtsStubServer(served, host="127.0.0.1", port=0)
        _, port = await server.start()
        served.start_heartbeat(50.0)
        ctl = MtsController(MtsControllerConfig(kind="mts", port=port, request_timeout=2.0,
                                                ramp_time=0.05, external_field="specimen"))
        await ctl.connect()
        try:
            correction, _ = loop(ctl)
            return [await correction.run((t,)) for t in TARGETS[:3]]
        finally:
            await ctl.close()
            await server.stop()
            await served.close()

    steps = run(scenario)
    assert [s.verdict.outcome for s in steps] == ["converged"] * 3
    assert all(s.residual <= 0.01 for s in steps)


def test_modbus_two_channels_each_corrected_on_its_own_register() -> None:
    async def scenario() -> StepCorrection:
        stiff = parse_rig_config(rig_description(frame={"stiffness": 48.0}))
        soft = parse_rig_config(rig_description(frame={"stiffness": 16.0}))
        served = [ServedRig(build_rig(stiff)), ServedRig(build_rig(soft))]
        server = ModbusRigServer(served, host="127.0.0.1", port=0)
        _, port = await server.start()
        for s in served:
            s.start_heartbeat(50.0)
        ctl = ModbusController(ModbusControllerConfig(
            kind="modbus", port=port, request_timeout=2.0, ramp_time=0.05,
            external_register=24), n_actuators=2)
        await ctl.connect()
        try:
            correction, _ = loop(ctl, max_correction=[2.0, 3.0])
            return await correction.run((4.0, -3.0))
        finally:
            await ctl.close()
            await server.stop()
            for s in served:
                await s.close()

    step = run(scenario)
    assert step.verdict.outcome == "converged" and step.residual <= 0.01
    first = step.iterations[0].measured  # each channel short by its own frame's compliance
    assert first[0] == pytest.approx(4.0 * 48 / 56, abs=1e-4)
    assert first[1] == pytest.approx(-3.0 * 16 / 24, abs=1e-4)


def test_sim_actuator_serve_serves_the_external_register(tmp_path: Path) -> None:
    """The process a lab starts: ``sim-actuator serve --protocol modbus --rig FILE``."""
    file = tmp_path / "rig.toml"
    file.write_text(toml(rig_description(frame={"stiffness": 48.0})), encoding="utf-8")
    port = free_ports(1)[0]
    proc = subprocess.Popen(
        [sys.executable, "-m", "sim_actuator.cli", "serve", "--protocol", "modbus", "--port",
         str(port), "--rig", str(file), "--time-scale", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        ready, _, _ = select.select([proc.stdout], [], [], 30.0)
        line = proc.stdout.readline() if ready else ""
        assert line.startswith("sim-actuator ready"), line

        async def scenario() -> list[StepCorrection]:
            ctl = ModbusController(ModbusControllerConfig(
                kind="modbus", port=port, request_timeout=2.0, ramp_time=0.05,
                external_register=24))
            await ctl.connect()
            try:
                correction, _ = loop(ctl)
                return [await correction.run((t,)) for t in (3.0, -2.0)]
            finally:
                await ctl.close()

        steps = run(scenario)
    finally:
        proc.terminate()
        proc.wait(10)
    assert [s.verdict.outcome for s in steps] == ["converged"] * 2
    first = steps[0].iterations[0].measured[0]
    assert first == pytest.approx(3.0 * 48 / 56, abs=1e-4)  # the specimen, behind the frame
    assert all(s.residual <= 0.01 for s in steps)


def test_a_two_actuator_rig_reads_each_specimen(tmp_path: Path) -> None:
    file = tmp_path / "rig.toml"
    file.write_text(toml(rig_description(frame={"stiffness": 48.0})), encoding="utf-8")
    controller = RigController(RigControllerConfig(file=file, external="specimen"), 2)
    controller.set_ctrl_now((2.0, -1.0))
    daq = controller.get_daq_now()
    assert daq.disp == pytest.approx((2.0, -1.0))  # the LVDT on the piston
    assert daq.external == pytest.approx((2.0 * 48 / 56, -1.0 * 48 / 56))
    assert RigController(RigControllerConfig(file=file), 2).get_daq_now().external is None


def test_max_correction_zero_only_checks(tmp_path: Path) -> None:
    correction, path = loop(rig(tmp_path, frame={"stiffness": 48.0}), max_correction=0.0)
    step = drive(correction, [0.001, 3.0])[-1]
    assert step.verdict.outcome == "beyond-max-correction" and path.sent == [(0.001,), (3.0,)]


def test_an_unmapped_external_register_is_a_clear_controller_error() -> None:
    async def scenario() -> str:
        async with modbus(compliant(), external_register=28) as ctl:
            with pytest.raises(ControllerError) as err:
                await ctl.get_daq()
            return str(err.value)

    message = run(scenario)
    assert "read the external channel (register 28)" in message
    assert "ILLEGAL_DATA_ADDRESS" in message
