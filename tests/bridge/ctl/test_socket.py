"""The control socket itself: JSON lines, bad requests answered (never a crash), a read deadline,
mode 0600, stale and live sockets, and the short-path fallback for long run directories."""

from __future__ import annotations

import json
import math
import os
import socket
import stat
import tempfile
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from fresco_bridge import ctl
from fresco_bridge.config import parse_config
from fresco_bridge.daemon import BridgeThread
from tests.support.bridge import RunningBridge


def _toml(extra: str = "") -> str:
    return textwrap.dedent("""
        [bridge]
        run_name = "sock"
        """) + extra + textwrap.dedent("""
        [[sites]]
        name = "a"
        port = 0
        [[sites]]
        name = "b"
        port = 0
        """)


@pytest.fixture
def short_dir() -> Iterator[Path]:
    with tempfile.TemporaryDirectory(prefix="fbctl") as d:
        yield Path(d)


@pytest.fixture
def bridge(short_dir: Path, tmp_path: Path) -> Iterator[BridgeThread]:
    toml = _toml(f'control_socket = "{short_dir / "c.sock"}"\n')
    with RunningBridge(toml, tmp_path) as b:
        yield b


def _lines(path: Path, *requests: bytes) -> list[dict[str, Any]]:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(5.0)
        s.connect(str(path))
        s.sendall(b"".join(requests))
        data = b""
        while data.count(b"\n") < len(requests):
            chunk = s.recv(65536)
            if not chunk:
                break
            data += chunk
    return [json.loads(line) for line in data.splitlines()]


def test_requests_and_bad_requests_on_one_connection(bridge: BridgeThread,
                                                     short_dir: Path) -> None:
    path = short_dir / "c.sock"
    answers = _lines(
        path,
        b'{"command": "status", "id": 1}\n',
        b"not json\n",
        b'["status"]\n',
        b'{"command": "status", "verbose": true}\n',
        b'{"command": "reboot"}\n',
        b'{"command": "pause", "site": "zz"}\n',
        b'{"command": "pause", "site": 3}\n',
        b'{"command": "pause", "site": "a", "id": "x"}\n',
        b'{"command": "resume"}\n',
    )
    assert answers[0]["ok"] and answers[0]["id"] == 1
    assert [s["site"] for s in answers[0]["sites"]] == ["a", "b"]
    assert "not a JSON line" in answers[1]["error"]
    assert "JSON object" in answers[2]["error"]
    assert "unknown key(s) ['verbose']" in answers[3]["error"]
    assert "unknown command 'reboot'" in answers[4]["error"]
    assert "no site 'zz'; sites: a, b" in answers[5]["error"]
    assert "site a string or null" in answers[6]["error"]
    assert answers[7]["ok"] and answers[7]["id"] == "x"
    # resume for every site: a was paused (ok), b was not (refused) → not ok overall
    resume = answers[8]
    assert not resume["ok"]
    assert [(r["site"], r["ok"]) for r in resume["results"]] == [("a", True), ("b", False)]
    assert bridge.call(lambda: str(bridge.bridge.sites["a"].state)) == "IDLE"


def test_deep_nesting_huge_numbers_and_bad_bytes_get_one_line_answers(
        bridge: BridgeThread, short_dir: Path, caplog: pytest.LogCaptureFixture) -> None:
    """4,000 ``[`` under the size cap raised RecursionError out of the client's task (a
    traceback, no reply): now every such line is answered, and the connection serves on."""
    answers = _lines(
        short_dir / "c.sock",
        b"[" * 4000 + b"\n",
        b'{"command": ' + b"[" * 17 + b"\n",
        b"9" * 4090 + b"\n",
        b'{"command": "status", "id": 1e999999}\n',
        b"\xff\xfe\n",
        b'{"command": "status", "id": "[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[["}\n',
    )
    assert [a["ok"] for a in answers] == [False, False, False, True, False, True]
    assert answers[0]["error"] == ("request is not a JSON line: nested deeper than 16 levels at "
                                   "character 16")
    assert "nested deeper" in answers[1]["error"] and "JSON object" in answers[2]["error"]
    assert answers[3]["id"] == math.inf  # a huge number is a number (inf), not an error
    assert "not UTF-8 at byte 0" in answers[4]["error"]
    assert "Traceback" not in caplog.text and "RecursionError" not in caplog.text
    assert all("\n" not in r.getMessage() for r in caplog.records)


def test_socket_is_private_to_the_bridge_user(bridge: BridgeThread, short_dir: Path) -> None:
    mode = stat.S_IMODE(os.stat(short_dir / "c.sock").st_mode)
    assert mode == 0o600


def test_a_silent_client_is_disconnected_after_the_read_deadline(
    bridge: BridgeThread, short_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(ctl, "READ_TIMEOUT", 0.3)
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(5.0)
        s.connect(str(short_dir / "c.sock"))
        t0 = time.monotonic()
        assert s.recv(1) == b""  # closed by the bridge, not by our 5 s timeout
        assert time.monotonic() - t0 < 4.0
    # and the bridge still serves the next client
    assert _lines(short_dir / "c.sock", b'{"command": "status"}\n')[0]["ok"]


def test_an_overlong_line_is_answered_and_closed(bridge: BridgeThread, short_dir: Path) -> None:
    (answer,) = _lines(short_dir / "c.sock", b"x" * (ctl.MAX_LINE + 10) + b"\n")
    assert "longer than" in answer["error"]


def test_a_live_socket_is_not_stolen_and_a_stale_one_is_replaced(
    bridge: BridgeThread, short_dir: Path, tmp_path: Path
) -> None:
    toml = _toml(f'control_socket = "{short_dir / "c.sock"}"\n')
    second = BridgeThread(parse_config(toml), toml, run_dir=tmp_path / "second")
    with pytest.raises(ctl.ControlError, match="served by another running bridge"):
        second.__enter__()
    stale = short_dir / "stale.sock"
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.bind(str(stale))
    s.close()  # a socket file nobody listens on: what a killed bridge leaves
    toml = _toml(f'control_socket = "{stale}"\n')
    with RunningBridge(toml, tmp_path / "third"):
        assert ctl.request(stale, "status")["ok"]
    assert not stale.exists()  # removed at shutdown


def test_long_run_directories_get_a_short_socket_and_a_pointer(tmp_path: Path) -> None:
    deep = tmp_path / ("d" * 60) / ("e" * 60)
    with RunningBridge(_toml(), deep) as b:
        run_dir = b.run_dir
        assert not (run_dir / ctl.SOCKET_NAME).exists()
        pointer = (run_dir / ctl.POINTER_NAME).read_text().strip()
        found = ctl.find_socket(None, run_dir, deep)
        assert str(found) == pointer and len(os.fsencode(found)) <= 107
        assert ctl.find_socket(None, None, deep) == found  # newest run under the root
        assert ctl.request(found, "status")["ok"]
    assert not (run_dir / ctl.POINTER_NAME).exists() and not found.exists()


def test_discovery_skips_a_stale_socket_of_a_newer_run(tmp_path: Path, short_dir: Path) -> None:
    runs = tmp_path / "runs"
    with RunningBridge(_toml(), runs) as b:
        live = ctl.find_socket(None, b.run_dir, runs)
        newer = runs / "99991231T000000-killed"
        newer.mkdir()
        stale = short_dir / "stale.sock"
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.bind(str(stale))
        s.close()  # what a bridge killed with -9 leaves behind
        (newer / ctl.POINTER_NAME).write_text(f"{stale}\n")
        os.utime(newer, (time.time() + 60, time.time() + 60))
        assert ctl.find_socket(None, None, runs) == live
        # named explicitly, the stale one is used and the error says what happened
        with pytest.raises(ctl.ControlError, match=r"stale\.sock"):
            ctl.request(ctl.find_socket(None, newer, runs), "status")


def test_the_shared_temp_fallback_directory_must_be_private(tmp_path: Path) -> None:
    d = tmp_path / "open"
    d.mkdir()
    d.chmod(0o777)
    with pytest.raises(ctl.ControlError, match="mode 0700"):
        ctl._check_private(d)
    d.chmod(0o700)
    ctl._check_private(d)


def test_ctl_prints_what_the_sites_quote_without_acting_on_the_terminal() -> None:
    answer = {"ok": False, "results": [{"site": "a", "ok": False,
                                        "message": "refused\x1b[2J\nfake: ok"}], "sites": []}
    assert ctl.format_answer(answer) == "a: REFUSED: refused\\x1b[2J\\nfake: ok"
    assert ctl.format_answer({"error": "no site 'x\u202e'"}) == "error: no site 'x\\u202e'"
