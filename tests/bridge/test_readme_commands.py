"""Every command of the README runs as written on a fresh clone after ``make demo`` (issue 27).

The README's convention, which this test enforces:

- Commands are fenced ```` ```sh ```` blocks (no ``bash``/``shell``/``console`` fences, which
  would escape this test). Each block is one shell script; ``\\`` continues a line, ``#``
  starts a comment. Programs of the project are called through ``.venv/bin/`` (what ``make
  demo`` creates), never a bare ``fresco-bridge`` or ``python`` a fresh machine lacks.
- A block preceded by ``<!-- readme-test: skip: REASON -->`` is only checked statically; the
  reason is mandatory. Every other block also runs for real.

Static checks, every block: each ``fresco-bridge`` command line parses with the real parser
(nothing runs); each repository file a command names exists; each ``make`` target exists; a
``pip install NAME==VERSION`` pins what ``pyproject.toml`` pins; ``python -m MODULE`` imports.
Neither the README nor ``examples/`` mentions ``../shared``.

For real: a scratch directory laid out as a fresh clone after ``make demo`` (the repository's
files linked in, ``.venv/bin/`` shims running this checkout, a short ``fresco-bridge demo`` run
under ``runs/``); the blocks run there in order with short settings (``LAB_DURATION=2``, free
lab ports) and a deadline. A ``fresco-bridge serve`` line is a terminal of its own: it starts
first, in the background, and the rest of the block runs once it printed its ready line; it
must still be serving at the block's end and stop cleanly on Ctrl-C (SIGINT).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import queue
import re
import shlex
import signal
import socket
import subprocess
import sys
import threading
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from fresco_bridge import cli
from tests.support.net import HOST, free_ports
from tests.support.paths import EXAMPLES, REPO

README = REPO / "README.md"
PROGRAMS = ("fresco-bridge", "sim-actuator", "python", "pip")
VENV_BIN = ".venv/bin/"
OUTPUT_FLAGS = {"-o", "--out", "--output", "--json", "--report", "--records", "--plot"}
BLOCK_DEADLINE = 900.0  # s for one block's script, on a loaded 2-core machine
READY_DEADLINE = 120.0  # s for a bridge's ready line
STOP_DEADLINE = 60.0  # s for a bridge to stop on SIGINT
SHARED_MENTIONS = ("../shared", "shared/data", "shared/fixtures", "shared/specs")


@dataclass(frozen=True)
class Command:
    line: int  # README line the command starts on
    text: str  # the logical line (continuations joined), comment included
    argv: list[str]  # shell words, comment removed


@dataclass(frozen=True)
class Block:
    line: int  # README line of the opening fence
    skip: str | None  # the reason, when the block is only checked statically
    commands: list[Command]

    @property
    def script(self) -> str:
        return "\n".join(c.text for c in self.commands)


def _marker(before: str, where: str) -> str | None:
    """The ``readme-test`` directive of the HTML comment right before a fence: a skip reason."""
    found = re.search(r"<!--\s*readme-test:(.*?)-->\s*\Z", before, re.S)
    if found is None:
        return None
    directive = " ".join(found.group(1).split())
    if not directive.startswith("skip:"):
        raise ValueError(f"{where}: unknown readme-test directive {directive!r} "
                         "(expected 'skip: REASON')")
    reason = directive.removeprefix("skip:").strip()
    if not reason:
        raise ValueError(f"{where}: a skipped block must say why ('skip: REASON')")
    return reason


def _commands(body: list[str], first_line: int, name: str) -> list[Command]:
    """The block's logical lines: a trailing backslash continues a line onto the next."""
    out: list[Command] = []
    pending: list[str] = []
    start = first_line
    for offset, raw in enumerate(body):
        if not pending:
            start = first_line + offset
        if raw.rstrip().endswith("\\"):
            pending.append(raw.rstrip()[:-1])
            continue
        text = " ".join(p.strip() for p in [*pending, raw]).strip()
        pending = []
        argv = shlex.split(text, comments=True)
        if argv:
            out.append(Command(start, text, argv))
    if pending:
        raise ValueError(f"{name}:{start}: a block ends inside a continued line")
    return out


def readme_blocks(text: str, name: str = "README.md") -> list[Block]:
    """Every ```sh block of ``text`` (the file ``name``); another shell dialect's fence is an
    error."""
    lines = text.splitlines()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        fence = lines[i].strip()
        if fence in ("```bash", "```shell", "```console", "```zsh", "```sh-session"):
            raise ValueError(f"{name}:{i + 1}: write command blocks as ```sh (got {fence})")
        if fence != "```sh":
            i += 1
            continue
        end = next(j for j in range(i + 1, len(lines)) if lines[j].strip() == "```")
        skip = _marker("\n".join(lines[:i]), f"{name}:{i + 1}")
        blocks.append(Block(i + 1, skip, _commands(lines[i + 1:end], i + 2, name)))
        i = end + 1
    return blocks


BLOCKS = readme_blocks(README.read_text(encoding="utf-8"))


def _program(argv: list[str]) -> str:
    return argv[0].removeprefix(VENV_BIN)


def _where(block: Block, command: Command | None = None) -> str:
    return f"README.md:{command.line if command else block.line}"


# -- static checks ------------------------------------------------------------------------------
def test_the_readme_has_command_blocks_and_its_skips_say_why() -> None:
    assert len(BLOCKS) >= 4
    assert any(b.skip is None for b in BLOCKS)
    assert all(b.commands for b in BLOCKS), "an empty ```sh block"
    with pytest.raises(ValueError, match="must say why"):
        readme_blocks("<!-- readme-test: skip: -->\n```sh\nls\n```\n")
    with pytest.raises(ValueError, match="unknown readme-test directive"):
        readme_blocks("<!-- readme-test: later -->\n```sh\nls\n```\n")
    with pytest.raises(ValueError, match="write command blocks as"):
        readme_blocks("```bash\nls\n```\n")


def test_the_readme_is_short_and_maps_every_page() -> None:
    """The README is the newcomer's path (issue 27: at most ~200 lines); the rest is linked."""
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    for page in sorted((REPO / "docs").glob("*.md")):
        if page.name not in ("index.md", "benchmarks.md"):  # the site's home; BENCHMARKS.md
            assert f"](docs/{page.name})" in text, f"the README does not link docs/{page.name}"
    assert "](BENCHMARKS.md)" in text
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
        if "://" not in target:
            assert (REPO / target).exists(), f"the README links {target}, which does not exist"


def test_nothing_points_at_shared() -> None:
    """The README and the examples work on a clone with nothing beside it. (A script under
    ``examples/data/`` that rebuilds the shipped data may name where the originals live.)"""
    files = [README, *(p for p in EXAMPLES.rglob("*") if p.is_file()
                       and not (p.parent.name == "data" and p.suffix == ".py"))]
    for path in files:
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue  # binary data
        for mention in SHARED_MENTIONS:
            assert mention not in text, f"{path.relative_to(REPO)} mentions {mention}"


def _all_commands() -> list[tuple[Block, Command]]:
    return [(b, c) for b in BLOCKS for c in b.commands]


def _ids(pairs: list[tuple[Block, Command]]) -> list[str]:
    return [f"L{c.line}:{_program(c.argv)}" for _, c in pairs]


COMMANDS = _all_commands()


@pytest.mark.parametrize(("block", "command"), COMMANDS, ids=_ids(COMMANDS))
def test_project_programs_come_from_the_venv(block: Block, command: Command) -> None:
    """A fresh clone has only what ``make demo`` installed, in ``.venv/bin``."""
    program = _program(command.argv)
    if program in PROGRAMS or command.argv[0] == "python3":
        assert command.argv[0].startswith(VENV_BIN), (
            f"{_where(block, command)}: call {command.argv[0]} as {VENV_BIN}{program}")


def _placeholders(word: str, script: str = "") -> str:
    """A shell variable, when a line is parsed (nothing runs): a ``for`` loop's first word, else
    a run directory (``run=$(ls -d runs/*-demo | tail -n 1)``)."""
    loops = dict(re.findall(r"\bfor (\w+) in (\S+)", script))
    return re.sub(r"\$\{?(\w+)\}?", lambda m: loops.get(m.group(1), "runs/20260101T000000-demo"),
                  word)


def parse_fresco_bridge(argv: list[str], monkeypatch: pytest.MonkeyPatch) -> argparse.Namespace:
    """``argv`` through the real ``fresco-bridge`` parser, the command itself not run."""
    parsed: list[argparse.Namespace] = []

    def capture(args: argparse.Namespace) -> int:
        parsed.append(args)
        return 0

    monkeypatch.setattr(cli, "_run", capture)
    monkeypatch.setattr(cli, "configure_logging", lambda verbose: None)
    try:
        assert cli.main(argv) == 0
    except SystemExit as stop:
        raise AssertionError(f"fresco-bridge {shlex.join(argv)}: does not parse "
                             f"(exit {stop.code})") from None
    return parsed[0]


def _repo_files(argv: list[str]) -> Iterator[str]:
    """The words of a command that name a file of the repository (not outputs, not runs)."""
    previous = ""
    for word in argv[1:]:
        value = word.split("=", 1)[1] if word.startswith("--") and "=" in word else word
        output = previous in OUTPUT_FLAGS
        previous = word
        if output or value.startswith("-") or "/" not in value or "://" in value:
            continue
        if any(ch in value for ch in "$*<>|()") or value.startswith(("runs/", "/")):
            continue
        yield value


@pytest.mark.parametrize(("block", "command"), COMMANDS, ids=_ids(COMMANDS))
def test_each_command_is_runnable_as_written(
        block: Block, command: Command, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    where = _where(block, command)
    argv = command.argv
    for name in _repo_files(argv):
        assert (REPO / name).exists(), f"{where}: {name} is not in the repository"
    program = _program(argv)
    if program == "fresco-bridge":
        parse_fresco_bridge([_placeholders(w, block.script) for w in argv[1:]], monkeypatch)
        assert "does not parse" not in capsys.readouterr().err
    elif program == "make":
        for target in argv[1:]:
            out = subprocess.run(["make", "-n", "-C", str(REPO), target], capture_output=True,
                                 text=True, timeout=120)
            assert out.returncode == 0, f"{where}: make {target}: {out.stderr}"
    elif program == "pip":
        pins = _pyproject_pins()
        for spec in (w for w in argv[2:] if "==" in w):
            name, version = spec.split("==")
            assert pins.get(name.lower()) == version, (
                f"{where}: {spec}, but pyproject.toml pins {name}=={pins.get(name.lower())}")
    elif program in ("python", "python3") and argv[1:2] == ["-m"]:
        assert importlib.util.find_spec(argv[2]) is not None, f"{where}: no module {argv[2]}"


def _pyproject_pins() -> dict[str, str]:
    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    specs = [*project["dependencies"], *(s for group in project["optional-dependencies"].values()
                                        for s in group)]
    pins: dict[str, str] = {}
    for spec in specs:
        found = re.match(r"([A-Za-z0-9_.\-]+)(?:\[[^\]]*\])?==([^;\s]+)", spec)
        if found:
            pins[found.group(1).lower()] = found.group(2)
    return pins


def test_the_make_targets_are_the_readmes() -> None:
    """``make demo`` runs the demo, ``make test`` also builds this documentation strictly."""
    for target, expect in (("demo", "fresco-bridge demo"), ("test", "mkdocs build --strict")):
        out = subprocess.run(["make", "-n", "-C", str(REPO), target], capture_output=True,
                             text=True, timeout=120)
        assert out.returncode == 0, out.stderr
        assert expect in out.stdout, f"make -n {target} does not run {expect!r}"


DOC_PAGES = sorted((REPO / "docs").glob("*.md"))
INCLUDED = {"benchmarks.md": "BENCHMARKS.md", "security.md": "SECURITY.md",
            "telemetry.md": "fresco_bridge/telemetry/README.md",
            "sim-actuator.md": "sim_actuator/README.md"}


def _doc_commands() -> list[tuple[str, Block, Command]]:
    """The ``fresco-bridge`` lines of the documentation's ```sh blocks (its included files too)."""
    files = [*(p.relative_to(REPO).as_posix() for p in DOC_PAGES), *INCLUDED.values()]
    return [(name, block, command) for name in files
            for block in readme_blocks((REPO / name).read_text(encoding="utf-8"), name)
            for command in block.commands if _program(command.argv) == "fresco-bridge"]


DOC_COMMANDS = _doc_commands()


def test_the_documentation_pages_are_the_sites() -> None:
    """Every page is in the site's navigation; an included page names the file it includes."""
    mkdocs = (REPO / "mkdocs.yml").read_text(encoding="utf-8")
    for page in DOC_PAGES:
        assert f": {page.name}" in mkdocs, f"docs/{page.name} is not in mkdocs.yml's nav"
    for name, included in INCLUDED.items():
        assert f'--8<-- "{included}"' in (REPO / "docs" / name).read_text(encoding="utf-8")
    assert len(DOC_COMMANDS) >= 20


@pytest.mark.parametrize(("name", "block", "command"), DOC_COMMANDS,
                         ids=[f"{n}:{c.line}" for n, _, c in DOC_COMMANDS])
def test_each_documented_command_parses(
        name: str, block: Block, command: Command, monkeypatch: pytest.MonkeyPatch) -> None:
    """The documentation's commands keep up with the parser (the README's also run)."""
    argv = [_placeholders(w, block.script) for w in command.argv[1:]]
    try:
        parse_fresco_bridge(argv, monkeypatch)
    except AssertionError as error:
        raise AssertionError(f"{name}:{command.line}: {error}") from None


def test_the_written_pages_need_nothing_beside_the_clone() -> None:
    for page in DOC_PAGES:
        if page.name in INCLUDED:
            continue  # BENCHMARKS.md's measurements may use ../shared; the pages never do
        text = page.read_text(encoding="utf-8")
        for mention in SHARED_MENTIONS:
            assert mention not in text, f"docs/{page.name} mentions {mention}"


# -- for real -----------------------------------------------------------------------------------
SHIM = '#!/bin/sh\nexec "{python}" {args} "$@"\n'
SHIMS = {
    "fresco-bridge": "-c 'import sys; from fresco_bridge.entry import main; "
                     "sys.exit(main(sys.argv[1:]))'",
    "sim-actuator": "-c 'import sys; from sim_actuator.cli import main; sys.exit(main())'",
    "python": "",
}
NOT_LINKED = {".git", ".venv", "runs", "build", "site", ".mypy_cache", ".ruff_cache",
              ".pytest_cache", ".hypothesis", "__pycache__"}


@pytest.fixture(scope="module")
def clone(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh clone after ``make demo``: the repository's files, ``.venv/bin``, a demo run."""
    root = tmp_path_factory.mktemp("clone")
    for entry in REPO.iterdir():
        if entry.name not in NOT_LINKED and not entry.name.endswith(".egg-info"):
            (root / entry.name).symlink_to(entry)
    venv_bin = root / ".venv" / "bin"
    venv_bin.mkdir(parents=True)
    for name, args in SHIMS.items():
        shim = venv_bin / name
        shim.write_text(SHIM.format(python=sys.executable, args=args), encoding="utf-8")
        shim.chmod(0o755)
    demo = subprocess.run([str(venv_bin / "fresco-bridge"), "demo", "--duration", "4"],
                          cwd=root, env=_env(), capture_output=True, text=True,
                          timeout=BLOCK_DEADLINE)
    assert demo.returncode == 0, f"the short demo failed:\n{demo.stdout}\n{demo.stderr}"
    assert list((root / "runs").glob("*-demo")), "the demo wrote no runs/*-demo directory"
    return root


def _env(extra: dict[str, str] | None = None) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    env.update(extra or {})
    return env


def _short_settings() -> dict[str, str]:
    """The lab's integrator runs 2 s of record, on ports nobody else holds."""
    bridge, story2, controller, mqtt = free_ports(4)
    return {"LAB_DURATION": "2", "LAB_BRIDGE_PORT": str(bridge), "LAB_STORY2_PORT": str(story2),
            "LAB_CONTROLLER_PORT": str(controller), "LAB_MQTT_PORT": str(mqtt)}


def _is_serve(command: Command) -> bool:
    return _program(command.argv) == "fresco-bridge" and command.argv[1:2] == ["serve"]


def _config_ports(clone: Path, argv: list[str]) -> list[int]:
    config = tomllib.loads((clone / argv[argv.index("--config") + 1]).read_text("utf-8"))
    return [int(site["port"]) for site in config.get("sites", []) if site.get("port")]


def _port_taken(port: int) -> bool:
    with socket.socket() as s:
        try:
            s.bind((HOST, port))
        except OSError:
            return True
    return False


class Bridge:
    """A ``serve`` line in its own terminal: started, read line by line, stopped by Ctrl-C."""

    def __init__(self, clone: Path, command: Command, env: dict[str, str]) -> None:
        self.command = command
        self.proc = subprocess.Popen(["bash", "-c", f"exec {command.text}"], cwd=clone, env=env,
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines: queue.Queue[str | None] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line)
        self.lines.put(None)

    def wait_ready(self) -> None:
        while True:
            try:
                line = self.lines.get(timeout=READY_DEADLINE)
            except queue.Empty:
                raise AssertionError(f"no ready line within {READY_DEADLINE} s from "
                                     f"{self.command.text}") from None
            if line is None:
                raise AssertionError(f"{self.command.text} exited:\n{self.output()}")
            self.seen.append(line)
            if line.startswith("fresco-bridge ready"):
                return

    def output(self) -> str:
        while True:
            try:
                line = self.lines.get_nowait()
            except queue.Empty:
                return "".join(self.seen)
            if line is not None:
                self.seen.append(line)

    def stop(self) -> int | None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            return self.proc.wait(timeout=STOP_DEADLINE)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=STOP_DEADLINE)
            return None


RUN_BLOCKS = [b for b in BLOCKS if b.skip is None]


@pytest.mark.timeout(3 * BLOCK_DEADLINE)
@pytest.mark.parametrize("block", RUN_BLOCKS, ids=[f"L{b.line}" for b in RUN_BLOCKS])
def test_each_block_runs_for_real(block: Block, clone: Path) -> None:
    env = _env(_short_settings())
    serves = [c for c in block.commands if _is_serve(c)]
    for command in serves:
        taken = [p for p in _config_ports(clone, command.argv) if _port_taken(p)]
        if taken:
            pytest.skip(f"{_where(block, command)}: port(s) {taken} of its config are in use "
                        "by another process")
    bridges: list[Bridge] = []
    try:
        for command in serves:
            bridges.append(Bridge(clone, command, env))
            bridges[-1].wait_ready()
        rest = "\n".join(c.text for c in block.commands if not _is_serve(c))
        if rest:
            out = subprocess.run(["bash", "-c", "set -euo pipefail\n" + rest], cwd=clone,
                                 env=env, capture_output=True, text=True,
                                 timeout=BLOCK_DEADLINE)
            assert out.returncode == 0, (
                f"{_where(block)}: exit {out.returncode}\n--- stdout\n{out.stdout[-4000:]}\n"
                f"--- stderr\n{out.stderr[-4000:]}")
        for bridge in bridges:
            assert bridge.proc.poll() is None, (
                f"{bridge.command.text} stopped during the block:\n{bridge.output()}")
    finally:
        codes = [(b, b.stop()) for b in bridges]
    for bridge, code in codes:
        assert code == 0, f"{bridge.command.text} ended with {code} on Ctrl-C:\n{bridge.output()}"
