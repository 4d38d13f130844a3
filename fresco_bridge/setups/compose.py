"""Setups made of setups: OpenFresco's scale factors around any setup, and ``Aggregator``
(several setups side by side on one control: trial, ctrl, daq and out vectors stacked in
the order the setups are listed)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from .base import Factors, Setup, Values, scale


class Scaled:
    """``inner`` with OpenFresco's factors: trial × trialFact → inner → × ctrlFact; daq ×
    daqFact → inner → × outFact."""

    identity = False

    def __init__(self, inner: Setup, factors: Factors) -> None:
        self.inner = inner
        self.kind = inner.kind
        self.n_basic = inner.n_basic
        self.n_actuators = inner.n_actuators
        nb, na = self.n_basic, self.n_actuators
        factors.check({"trial": nb, "out": nb, "ctrl": na, "daq": na})
        self._f = {key: factors.get(key, nb if side in ("trial", "out") else na)
                   for side in ("trial", "out", "ctrl", "daq")
                   for key in (f"{side}{sig}Fact" for sig in ("Disp", "Vel", "Accel", "Force"))}

    def ctrl_disp(self, trial_disp: Values) -> Values:
        f = self._f
        return scale(self.inner.ctrl_disp(scale(trial_disp, f["trialDispFact"])),
                     f["ctrlDispFact"])

    def ctrl_vel(self, trial_disp: Values, trial_vel: Values) -> Values:
        f = self._f
        return scale(self.inner.ctrl_vel(scale(trial_disp, f["trialDispFact"]),
                                         scale(trial_vel, f["trialVelFact"])), f["ctrlVelFact"])

    def ctrl_accel(self, trial_disp: Values, trial_vel: Values, trial_accel: Values) -> Values:
        f = self._f
        return scale(self.inner.ctrl_accel(scale(trial_disp, f["trialDispFact"]),
                                           scale(trial_vel, f["trialVelFact"]),
                                           scale(trial_accel, f["trialAccelFact"])),
                     f["ctrlAccelFact"])

    def out_disp(self, trial_disp: Values, ctrl: Values, daq_disp: Values) -> Values:
        f = self._f
        trial = scale(trial_disp, f["trialDispFact"])
        inner_ctrl = self.inner.ctrl_disp(trial)  # the ctrl before ctrlDispFact
        return scale(self.inner.out_disp(trial, inner_ctrl, scale(daq_disp, f["daqDispFact"])),
                     f["outDispFact"])

    def out_vel(self, daq_vel: Values) -> Values:
        f = self._f
        return scale(self.inner.out_vel(scale(daq_vel, f["daqVelFact"])), f["outVelFact"])

    def out_accel(self, daq_accel: Values) -> Values:
        f = self._f
        return scale(self.inner.out_accel(scale(daq_accel, f["daqAccelFact"])),
                     f["outAccelFact"])

    def basic_force(self, daq_force: Values, daq_disp: Values | None = None) -> Values:
        f = self._f
        disp = None if daq_disp is None else scale(daq_disp, f["daqDispFact"])
        return scale(self.inner.basic_force(scale(daq_force, f["daqForceFact"]), disp),
                     f["outForceFact"])

    def basic_matrix(self, k_act: Values) -> Values:
        """diag(outForce) · inner(diag(daqForce) k diag(ctrlDisp)) · diag(trialDisp)."""
        f, na, nb = self._f, self.n_actuators, self.n_basic
        k = np.array(k_act, dtype=np.float64).reshape(na, na, order="F")
        k = _diag(f["daqForceFact"], na) @ k @ _diag(f["ctrlDispFact"], na)
        inner = self.inner.basic_matrix(tuple(k.ravel(order="F").tolist()))
        kb = np.array(inner, dtype=np.float64).reshape(nb, nb, order="F")
        kb = _diag(f["outForceFact"], nb) @ kb @ _diag(f["trialDispFact"], nb)
        return tuple(kb.ravel(order="F").tolist())


def _diag(factors: Sequence[float] | None, n: int) -> npt.NDArray[np.float64]:
    return np.eye(n) if factors is None else np.diag(np.asarray(factors, dtype=np.float64))


class Aggregator:
    """Setups side by side: setup ``i`` takes the next ``n_basic_i`` trial components and
    the next ``n_actuators_i`` actuators."""

    identity = False
    kind = "Aggregator"

    def __init__(self, parts: Sequence[Setup]) -> None:
        self.parts = tuple(parts)
        self.n_basic = sum(p.n_basic for p in self.parts)
        self.n_actuators = sum(p.n_actuators for p in self.parts)
        self._b: list[slice] = []
        self._a: list[slice] = []
        b = a = 0
        for p in self.parts:
            self._b.append(slice(b, b + p.n_basic))
            self._a.append(slice(a, a + p.n_actuators))
            b, a = b + p.n_basic, a + p.n_actuators

    def _zip(self) -> zip[tuple[Setup, slice, slice]]:
        return zip(self.parts, self._b, self._a, strict=True)

    def ctrl_disp(self, trial_disp: Values) -> Values:
        return tuple(v for p, b, _ in self._zip() for v in p.ctrl_disp(trial_disp[b]))

    def ctrl_vel(self, trial_disp: Values, trial_vel: Values) -> Values:
        return tuple(v for p, b, _ in self._zip()
                     for v in p.ctrl_vel(trial_disp[b], trial_vel[b]))

    def ctrl_accel(self, trial_disp: Values, trial_vel: Values, trial_accel: Values) -> Values:
        return tuple(v for p, b, _ in self._zip()
                     for v in p.ctrl_accel(trial_disp[b], trial_vel[b], trial_accel[b]))

    def out_disp(self, trial_disp: Values, ctrl: Values, daq_disp: Values) -> Values:
        return tuple(v for p, b, a in self._zip()
                     for v in p.out_disp(trial_disp[b], ctrl[a], daq_disp[a]))

    def out_vel(self, daq_vel: Values) -> Values:
        return tuple(v for p, _, a in self._zip() for v in p.out_vel(daq_vel[a]))

    def out_accel(self, daq_accel: Values) -> Values:
        return tuple(v for p, _, a in self._zip() for v in p.out_accel(daq_accel[a]))

    def basic_force(self, daq_force: Values, daq_disp: Values | None = None) -> Values:
        return tuple(v for p, _, a in self._zip()
                     for v in p.basic_force(daq_force[a],
                                            None if daq_disp is None else daq_disp[a]))

    def basic_matrix(self, k_act: Values) -> Values:
        """Block-diagonal: each setup's own actuators' block (coupling between setups through
        the specimen is the specimen's, not the setups')."""
        na, nb = self.n_actuators, self.n_basic
        k = np.array(k_act, dtype=np.float64).reshape(na, na, order="F")
        out = np.zeros((nb, nb))
        for p, b, a in self._zip():
            block = k[a, a].ravel(order="F").tolist()
            part = np.array(p.basic_matrix(tuple(block)), dtype=np.float64)
            out[b, b] = part.reshape(p.n_basic, p.n_basic, order="F")
        return tuple(out.ravel(order="F").tolist())
