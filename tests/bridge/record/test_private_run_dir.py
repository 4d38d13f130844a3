"""Secrets and file modes of the run directory, and its live/closed state.

The config snapshot never holds a secret (every ``SecretStr`` of the validated config is
redacted from the text, comments included); the run directory is 0700 and its files 0600
whatever the umask; the control socket stays 0600.
"""

from __future__ import annotations

import json
import os
import stat
import textwrap
import tomllib
from pathlib import Path

import pytest

from fresco_bridge.config import parse_config
from fresco_bridge.config_model import REDACTED, redact_config_text, secret_values
from fresco_bridge.record import RecordError, RunRecord, read_record
from fresco_bridge.record.recovery import is_locked, run_state
from tests.support.bridge import RunningBridge

PASSWORD = "broker-pass-0xC0FFEE"
TOKEN = "operator-token-0123456789"

CONFIG = textwrap.dedent(f"""
    [bridge]
    run_name = "private"
    [telemetry]
    username = "lab"
    password = "{PASSWORD}"   # the broker's
    # rotated on Mondays; old one was '{PASSWORD}'
    command_token = '''{TOKEN}'''
    [[sites]]
    name = "s"
    port = 0
    """)


def test_the_snapshot_holds_no_secret_and_the_run_directory_is_private(tmp_path: Path) -> None:
    old = os.umask(0o022)
    try:
        with RunningBridge(CONFIG, tmp_path) as bridge:
            run = bridge.run_dir
            sock = run / "control.sock"
            assert stat.S_IMODE(sock.stat().st_mode) == 0o600
            modes = {p.name: stat.S_IMODE(p.stat().st_mode) for p in run.iterdir()
                     if p.is_file()}
            assert json.loads((run / "run.json").read_text())["state"] == "running"
            assert run_state(run) == "running" and is_locked(run)
    finally:
        os.umask(old)
    assert stat.S_IMODE(run.stat().st_mode) == 0o700
    assert modes == {"config.toml": 0o600, "run.json": 0o600, "record.jsonl": 0o600}
    snapshot = (run / "config.toml").read_text()
    assert PASSWORD not in snapshot and TOKEN not in snapshot
    parsed = tomllib.loads(snapshot)["telemetry"]
    assert parsed["password"] == REDACTED and parsed["command_token"] == REDACTED
    assert parsed["username"] == "lab" and "# the broker's" in snapshot  # the rest is kept
    assert json.loads((run / "run.json").read_text())["state"] == "closed"
    assert run_state(run) == "closed" and not is_locked(run)
    assert all(PASSWORD not in p.read_text(errors="replace") for p in run.iterdir())


def test_secret_values_walks_the_whole_config() -> None:
    cfg = parse_config(CONFIG)
    assert dict(secret_values(cfg)) == {"telemetry.password": PASSWORD,
                                        "telemetry.command_token": TOKEN}


@pytest.mark.parametrize("text", [
    f'password = "{PASSWORD}"\n',
    f"password = '{PASSWORD}'\n",
    f'password = """{PASSWORD}"""\n',
    f'password = "{PASSWORD}" # {PASSWORD}\n',
    f'x = "prefix {PASSWORD} suffix"\n',
    f'password = """\n{PASSWORD}"""\n',
    f'password = "{PASSWORD[:5]}\\u0062{PASSWORD[6:]}"\n'.replace("\\u0062", PASSWORD[5]),
])
def test_redaction_never_leaves_a_secret(text: str) -> None:
    out = redact_config_text(text, [PASSWORD])
    assert PASSWORD not in out
    tomllib.loads(out)  # still a valid snapshot


def test_a_run_is_locked_by_its_bridge(tmp_path: Path) -> None:
    record = RunRecord.create(tmp_path, "lock", "", {})
    with pytest.raises(RecordError, match="in use by another running bridge"):
        RunRecord(record.directory)
    with pytest.raises(RecordError, match="in use"):
        RunRecord.resume(record.directory)
    record.event("s", 1, "session-open", "x")
    record.close()
    again = RunRecord.resume(record.directory)  # a closed run may be continued on purpose
    again.event("s", 2, "session-open", "y")
    again.close()
    meta = json.loads((record.directory / "run.json").read_text())
    assert meta["state"] == "closed" and meta["resumed"][0]["after_state"] == "closed"
    seqs = [r["seq"] for r in read_record(record.directory)]  # format 2: seq is implicit
    assert seqs == [1, 2]
