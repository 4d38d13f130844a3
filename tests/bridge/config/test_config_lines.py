"""A configuration error says where to edit: the line, and the site by its name (issue 36:
``sites[0]`` alone sent a person counting ``[[sites]]`` tables)."""

from __future__ import annotations

import pytest

from fresco_bridge.config import ConfigError, parse_config

LAB = """\
[bridge]
run_name = "x"
controller_timeout = -1

[[sites]]
name = "a"
port = 8092
[sites.controller]
model = "bilinear"
params = { k0 = 20.0, fy = 15.0, alpha = 0.05 }

[[sites]]
name = "b"
port = 8093
bogus = 1
[sites.controller]
kind = "nope"
"""


def test_each_problem_names_its_line_and_its_site() -> None:
    with pytest.raises(ConfigError) as err:
        parse_config(LAB, "lab.toml")
    lines = str(err.value).splitlines()
    assert lines[0] == "lab.toml: invalid configuration (3 problem(s))"
    assert "  line 3: bridge.controller_timeout: Input should be greater than 0 (got -1)" in lines
    assert "  line 15, site b: sites[1].bogus: unknown key (typo?)" in lines
    assert any(ln.startswith("  line 16, site b: sites[1].controller: unknown controller kind "
                             "'nope'") for ln in lines)


def test_a_key_in_a_sub_table_is_found_in_it() -> None:
    text = LAB.replace("controller_timeout = -1\n", "").replace(
        "params = { k0 = 20.0", "params = { k0 = -20.0").replace(
        'bogus = 1\n[sites.controller]\nkind = "nope"\n',
        '[sites.controller]\nmodel = "elastic"\nparams = { k = 1.0 }\n')
    with pytest.raises(ConfigError) as err:
        parse_config(text, "lab.toml")
    assert "  line 7, site a: sites[0].controller: bilinear: k0 must be > 0" in str(err.value)
