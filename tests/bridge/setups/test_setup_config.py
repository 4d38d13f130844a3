"""``[sites.setup]`` tables in lab.toml: OpenFresco's names, and errors that say file, key and
reason (a setup whose actuator count the controller cannot drive, an element of the wrong
size, a misspelt parameter, a setup the bridge does not build)."""

from __future__ import annotations

from pathlib import Path

import pytest

from fresco_bridge.config import ConfigError, load_config
from fresco_bridge.setups import make_setup
from fresco_bridge.sites.experimental_kind import site_controller as make_controller

SITE = '[[sites]]\nname = "column"\nport = 1\n'
COLUMN = ('[sites.setup]\nkind = "ThreeActuators2d"\nLa1 = 1000.0\nLa2 = 900.0\nLa3 = 900.0\n'
          'L1 = 500.0\nL2 = 500.0\nnlGeom = true\nposAct1 = "right"\nphiLocX = 90.0\n'
          'daqForceFact = [1.0, -1.0, -1.0]\n')


def load(tmp_path: Path, text: str) -> object:
    path = tmp_path / "lab.toml"
    path.write_text(text, encoding="utf-8")
    return load_config(path)


def error(tmp_path: Path, text: str) -> str:
    with pytest.raises(ConfigError) as err:
        load(tmp_path, text)
    message = str(err.value)
    assert message.startswith(f"{tmp_path / 'lab.toml'}: ")  # the file first
    return message


def test_a_tcl_expsetup_line_is_one_table(tmp_path: Path) -> None:
    cfg, _ = load(tmp_path, SITE + "dofs = 3\n" + COLUMN + '[sites.controller]\nkind = "sim"\n'
                  'model = "elastic"\nparams = { k = 5.0 }\n')  # type: ignore[misc]
    site = cfg.sites[0]
    assert str(site.setup) == "ThreeActuators2d"
    setup = make_setup(site.setup, site.dofs)
    assert setup.n_actuators == 3
    assert make_controller(site).n_actuators == 3  # one elastic law per actuator


def test_an_actuator_count_the_controller_cannot_drive(tmp_path: Path) -> None:
    message = error(tmp_path, SITE + "dofs = 3\n" + COLUMN
                    + '[sites.controller]\nkind = "rig"\n'
                    + '[[sites.controller.channels]]\npreset = "ideal-elastic"\n' * 2)
    assert ("site column: sites[0]: controller rig has 2 [[sites.controller.channels]] "
            "table(s); this site needs one per actuator: 3") in message


def test_limits_for_an_actuator_the_setup_does_not_have(tmp_path: Path) -> None:
    message = error(tmp_path, SITE + "dofs = 3\n" + COLUMN
                    + "[[sites.limits]]\nactuator = 4\ndisp_max = 50.0\n")
    assert ("sites[0]: limits: actuator 4 does not exist (setup ThreeActuators2d with 3 DOF(s) "
            "drives 3 actuator(s))") in message


def test_an_element_of_the_wrong_size(tmp_path: Path) -> None:
    message = error(tmp_path, SITE + "dofs = 2\n" + COLUMN)
    assert ("sites[0]: ThreeActuators2d serves an element of 3 basic DOFs (set the site's "
            "dofs = 3); this site has 2") in message


def test_a_misspelt_or_missing_parameter_is_named(tmp_path: Path) -> None:
    text = SITE + "dofs = 3\n" + COLUMN.replace("L2 = 500.0\n", "l2 = 500.0\n")
    message = error(tmp_path, text)
    assert "sites[0].setup: ThreeActuators2d: L2: Field required; l2: unknown key (typo?)" \
        in message
    message = error(tmp_path, SITE + "dofs = 3\n" + COLUMN.replace("1000.0", "-1000.0"))
    assert "sites[0].setup: ThreeActuators2d: La1: Input should be greater than 0" in message


def test_unknown_and_uncovered_setups(tmp_path: Path) -> None:
    message = error(tmp_path, SITE + '[sites.setup]\nkind = "ThreeActuator2d"\n')
    assert "sites[0].setup: kind: unknown setup kind 'ThreeActuator2d'; expected one of " \
           "NoTransformation, OneActuator, TwoActuators2d" in message
    message = error(tmp_path, SITE + '[sites.setup]\nkind = "FourActuators3d"\n')
    assert "kind: FourActuators3d is not supported by the bridge" in message
    message = error(tmp_path, SITE + 'setup = "ThreeActuators2d"\n')
    assert "sites[0].setup" in message


def test_a_factor_list_of_the_wrong_length(tmp_path: Path) -> None:
    message = error(tmp_path, SITE + "dofs = 3\n" + COLUMN.replace(
        "daqForceFact = [1.0, -1.0, -1.0]", "daqForceFact = [1.0, -1.0]"))
    assert "sites[0]: daqForceFact: 2 factors for a signal of 3 components" in message


def test_the_configuration_table_is_the_setup_registry() -> None:
    from fresco_bridge.setups.kinds import SETUP_TABLES, setup_kinds_markdown
    from tests.support.paths import REPO

    reference = (REPO / "docs" / "configuration.md").read_text(encoding="utf-8")
    assert f"| `[sites.setup] kind` | — | {setup_kinds_markdown()};" in reference
    mapping = (REPO / "docs" / "openfresco-setups.md").read_text(encoding="utf-8")
    assert all(f"`{name}`" in mapping for name in SETUP_TABLES)
