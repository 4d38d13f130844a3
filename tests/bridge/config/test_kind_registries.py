"""The controller-kind and model-kind registries: config validation, error texts and the
configuration reference's table (docs/configuration.md) all come from them."""

from __future__ import annotations

import pytest

from fresco_bridge.config import ConfigError, parse_config
from fresco_bridge.controls.registry import (
    CONTROLLER_KINDS,
    controller_kind,
    controller_kinds_markdown,
)
from fresco_bridge.sites.experimental_kind import site_controller as make_controller
from sim_actuator.models import MODEL_KINDS, model_kinds_markdown
from tests.support.paths import REPO

SITE = '[[sites]]\nname = "a"\nport = 1\n'


def test_the_configuration_table_is_the_registries() -> None:
    readme = (REPO / "docs" / "configuration.md").read_text(encoding="utf-8")
    assert f"| `[sites.controller] kind` | `\"sim\"` | {controller_kinds_markdown()} |" in readme
    assert f"| `controller.model` | `\"bilinear\"` | {model_kinds_markdown()}" in readme
    for name in (*CONTROLLER_KINDS, *MODEL_KINDS):
        assert f"`{name}`" in readme


def test_an_unknown_kind_names_every_registered_kind() -> None:
    with pytest.raises(ConfigError) as err:
        parse_config(SITE + '[sites.controller]\nkind = "rg"\n')
    assert "unknown controller kind 'rg'; expected sim, rig, modbus, mts or generic-tcp" in str(
        err.value)
    with pytest.raises(ValueError, match="expected sim, rig, modbus, mts or generic-tcp"):
        controller_kind("servo")


@pytest.mark.parametrize("kind", ["rig", "modbus", "mts"])
def test_a_typo_inside_a_kinds_table_is_reported_under_its_own_key(kind: str) -> None:
    extra = 'preset = "ideal"\n' if kind == "rig" else ""
    with pytest.raises(ConfigError) as err:
        parse_config(SITE + f'[sites.controller]\nkind = "{kind}"\n{extra}ramp = 1.0\n')
    assert "sites[0].controller.ramp: unknown key (typo?)" in str(err.value)


def test_the_actuator_count_comes_from_the_setup() -> None:
    two_dofs = SITE + "dofs = 2\n"
    with pytest.raises(ConfigError, match=r"controller rig has 1 \[\[sites.controller.channels"
                                          r"\]\] table\(s\); this site needs one per actuator: "
                                          r"2 \(setup NoTransformation with 2 DOF\(s\)\)"):
        parse_config(two_dofs + '[sites.controller]\nkind = "rig"\n'
                     '[[sites.controller.channels]]\npreset = "ideal-elastic"\n')
    one_actuator = parse_config(two_dofs + 'setup = "OneActuator"\n[sites.controller]\n'
                                'kind = "modbus"\n').sites[0]
    assert make_controller(one_actuator).n_actuators == 1
    for kind in ("modbus", "mts", "generic-tcp"):  # a channel per actuator
        site = parse_config(two_dofs + f'[sites.controller]\nkind = "{kind}"\n').sites[0]
        assert make_controller(site).n_actuators == 2
    sim = parse_config(two_dofs + '[sites.controller]\nmodel = "elastic"\n'
                       'params = { k = 2.0 }\n').sites[0]
    assert make_controller(sim).n_actuators == 2  # one specimen model per actuator
