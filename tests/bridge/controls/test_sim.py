"""The in-process ``sim`` controller's load cell: seeded noise on each force reading, one draw
per trial, as the study's ``MeasuredElement`` reads its ``Sensor``."""

from __future__ import annotations

import numpy as np
import pytest

from fresco_bridge.config import ConfigError, parse_config
from fresco_bridge.controls.registry import make_controller
from fresco_bridge.controls.sim import SimController
from sim_actuator.effects import Sensor
from sim_actuator.models import make_model

PARAMS = {"k0": 8.0, "fy": 12.0, "alpha": 0.05}


def readings(controller: SimController, path: list[float]) -> list[float]:
    out = []
    for d in path:
        controller.set_ctrl_now((d,))
        out.append(controller.get_daq_now().force[0])
        assert controller.get_daq_now().force[0] == out[-1]  # a second read: the same sample
        controller.commit_now()
    return out


def test_noise_is_the_study_sensors_stream_one_draw_per_trial() -> None:
    path = [0.5 * i for i in range(1, 8)]
    noisy = readings(SimController.from_params(1, "bilinear", PARAMS, load_cell_noise=0.1,
                                               noise_seed=7), path)
    law, cell = make_model("bilinear", **PARAMS), Sensor(noise_std=0.1,
                                                         rng=np.random.default_rng(7))
    expected = []
    for d in path:
        expected.append(cell.read(law.set_trial(d)[0]))
        law.commit()
    assert noisy == expected and len(noisy) == len(path)
    exact = readings(SimController.from_params(1, "bilinear", PARAMS), path)
    assert exact != noisy and max(abs(a - b) for a, b in zip(exact, noisy, strict=True)) < 0.5


def test_each_actuator_has_its_own_stream() -> None:
    two = SimController.from_params(2, "bilinear", PARAMS, load_cell_noise=0.1, noise_seed=1)
    two.set_ctrl_now((1.0, 1.0))
    f1, f2 = two.get_daq_now().force
    assert f1 != f2  # same law, same displacement: only the noise differs


def test_configured_from_lab_toml() -> None:
    cfg = parse_config('[[sites]]\nname = "s"\nport = 0\n[sites.controller]\nkind = "sim"\n'
                       'load_cell_noise = 0.2\nnoise_seed = 4\n')
    controller = make_controller(cfg.sites[0].controller, 1)
    assert isinstance(controller, SimController)
    controller.set_ctrl_now((0.0,))
    assert controller.get_daq_now().force[0] != 0.0
    with pytest.raises(ConfigError, match="load_cell_noise"):
        parse_config('[[sites]]\nname = "s"\nport = 0\n[sites.controller]\nkind = "sim"\n'
                     'load_cell_noise = -1\n')
