"""The site family: one registry of kinds (config union, error texts, docs row), and the
layering that keeps each kind's types inside its own package: nothing outside ``twins/``
names the twin's types, nothing outside ``sites/`` names ``ExperimentalSite``, and the daemon,
``ctl``, the transports and telemetry hold ``Site`` only."""

from __future__ import annotations

import ast
import re

import pytest

from fresco_bridge.config import ConfigError, parse_config
from fresco_bridge.site_kinds import SITE_KINDS, known_site_kinds, site_kind, site_kinds_markdown
from tests.support.paths import REPO

PACKAGE = REPO / "fresco_bridge"
TWIN_TYPES = ("TwinController", "Learner", "LearnerState", "LearnerSpec", "TwinSpec",
              "TwinGroup", "UpdatableSiteConfig", "SourceFeed", "TwinHost")


def _names_in(path: str) -> set[str]:
    """Every identifier and imported name of a module (its code, not its docstrings)."""
    tree = ast.parse((REPO / path).read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            names.add(node.id)
        elif isinstance(node, ast.Attribute):
            names.add(node.attr)
        elif isinstance(node, ast.alias):
            names.add(node.asname or node.name.split(".")[-1])
    return names


def _modules(outside: str) -> list[str]:
    return sorted(str(p.relative_to(REPO)) for p in PACKAGE.rglob("*.py")
                  if not str(p.relative_to(PACKAGE)).startswith(outside))


def test_nothing_outside_twins_names_the_twins_types() -> None:
    found = {m: sorted(_names_in(m) & set(TWIN_TYPES)) for m in _modules("twins/")}
    allowed = {"fresco_bridge/site_kinds.py"}  # the registry line imports the kind's KIND only
    assert {m: n for m, n in found.items() if n and m not in allowed} == {}


def test_nothing_outside_sites_names_the_experimental_site() -> None:
    found = [m for m in _modules("sites/") if "ExperimentalSite" in _names_in(m)]
    assert found == []


@pytest.mark.parametrize("module", ["fresco_bridge/daemon.py", "fresco_bridge/ctl.py",
                                    "fresco_bridge/server/connection.py",
                                    "fresco_bridge/server/handlers.py",
                                    "fresco_bridge/telemetry/taps.py"])
def test_the_daemon_ctl_transports_and_telemetry_hold_site_only(module: str) -> None:
    names = _names_in(module)
    assert not names & {"ExperimentalSite", "controller", "guard", *TWIN_TYPES}, module


def test_no_isinstance_on_a_site_kind_outside_its_module() -> None:
    pattern = re.compile(r"kind\s*==\s*[\"'](experimental|updatable)[\"']")
    hits = [m for m in _modules("twins/") if not m.startswith("fresco_bridge/sites/")
            and pattern.search((REPO / m).read_text(encoding="utf-8"))]
    assert hits == []


def test_a_config_with_an_unknown_kind_names_the_known_ones() -> None:
    with pytest.raises(ConfigError) as err:
        parse_config('[[sites]]\nname = "s"\nport = 0\nkind = "numerical"\n')
    assert (f"sites[0]: unknown site kind 'numerical'; expected {known_site_kinds()}"
            in str(err.value))
    assert known_site_kinds() == "experimental or updatable"
    with pytest.raises(ValueError, match="expected experimental or updatable"):
        site_kind("numerical")


def test_each_kind_has_its_config_its_factory_and_its_docs_row() -> None:
    docs = (REPO / "docs" / "configuration.md").read_text(encoding="utf-8")
    assert f"| `sites.kind` | `\"experimental\"` | {site_kinds_markdown()} |" in docs
    for name, kind in SITE_KINDS.items():
        assert kind.config.model_fields["kind"].annotation.__args__ == (name,)  # type: ignore[union-attr]
        assert callable(kind.factory) and kind.summary


def test_a_kind_only_takes_its_own_keys() -> None:
    with pytest.raises(ConfigError, match=r"sites\[0\]\.updater: a key of kind = \"updatable\""):
        parse_config('[[sites]]\nname = "s"\nport = 0\nupdater = "none"\n')
    cfg = parse_config('[[sites]]\nname = "s"\nport = 0\n[[sites]]\nname = "t"\nport = 0\n'
                       'kind = "updatable"\nlearns_from = "s"\nupdater = "none"\n')
    assert [s.kind for s in cfg.sites] == ["experimental", "updatable"]
    assert not hasattr(cfg.sites[1], "controller")


def test_a_resumed_site_shows_its_real_step_before_its_first_session() -> None:
    from fresco_bridge.sites.experimental import ExperimentalSite
    from fresco_bridge.sites.experimental_kind import site_controller

    (cfg,) = parse_config('[[sites]]\nname = "s"\nport = 0\n').sites
    site = ExperimentalSite(cfg, site_controller(cfg), None,  # type: ignore[arg-type]
                            controller_timeout=1.0)
    site.resume_from(1, 600, 6.0)
    status = site.status()
    assert (status["session"], status["step"], status["time"]) == (1, 600, 6.0)
    assert site.open_session("127.0.0.1:1") == 2 and site.step == 600


def test_every_kind_holds_the_one_site_core_which_names_no_kind() -> None:
    """``sites/core.py`` knows its kind's step path only as ``StepPath``; an experimental site
    and a twin's site each hold a ``SiteCore`` (composed, not inherited): one code for both."""
    from fresco_bridge.sites.core import SiteCore
    from fresco_bridge.sites.kind import SiteContext

    names = _names_in("fresco_bridge/sites/core.py")
    assert not names & {"ExperimentalSite", "controller", "guard", "gate", "setup", *TWIN_TYPES}
    cfg = parse_config('[[sites]]\nname = "s"\nport = 0\n[[sites]]\nname = "t"\nport = 0\n'
                       'kind = "updatable"\nlearns_from = "s"\nupdater = "none"\n')
    context = SiteContext(None, 1.0, 0.0)
    for kind in SITE_KINDS.values():
        group = kind.build([c for c in cfg.sites if c.kind == kind.name], context)
        (site,) = group.sites.values()
        core = getattr(site, "core")  # noqa: B009 (not part of ``Site``: the kind's own)
        assert type(core) is SiteCore and core.path is site
        assert not any(isinstance(site, SiteCore) for site in group.sites.values())
