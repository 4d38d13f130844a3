"""``fresco-bridge lab integrate`` against a real bridge: its summary, and a refused session.

A site whose sizes do not fit the client (a 1-DOF site; the integrator is a 2-DOF
genericClient) is refused by the bridge, which closes the connection without a reason (the
protocol has no message for one): the client says the bridge refused the session, with what it
knows, instead of a protocol-state error from its own cleanup.
"""

from __future__ import annotations

import io
import json
import subprocess
import sys
from pathlib import Path

from fresco_bridge.lab import run_integrator
from tests.support.bridge import RunningBridge
from tests.support.paths import REPO

SITE = """
[bridge]
run_name = "integrate"

[[sites]]
name = "damper"
port = 0
dofs = {dofs}
setup = "{setup}"
[sites.controller]
model = "bilinear"
params = {{ k0 = 6.8, fy = 12.0, alpha = 0.05 }}
"""


def test_the_summary_counts_steps_as_an_integer(tmp_path: Path) -> None:
    with RunningBridge(SITE.format(dofs=2, setup="OneActuator"), tmp_path) as bridge:
        out = io.StringIO()
        summary = run_integrator("127.0.0.1", bridge.ports["damper"], duration=0.5, pga=3.0,
                                 seed=1, connect_timeout=10.0, out=out)
    line = out.getvalue().strip()
    assert line.startswith("integrator: {"), line
    printed = json.loads(line.removeprefix("integrator: "))
    assert printed == summary and printed["steps"] == 50 and '"steps": 50,' in line
    assert isinstance(printed["steps"], int)
    # a person reads this line: 4 significant digits, not 5.887515649000079
    assert all(len(repr(v).replace(".", "").lstrip("0")) <= 5 for v in printed.values()), line


def test_a_site_whose_sizes_do_not_fit_is_a_refused_session(tmp_path: Path) -> None:
    with RunningBridge(SITE.format(dofs=1, setup="NoTransformation"), tmp_path) as bridge:
        proc = subprocess.run(
            [sys.executable, "-m", "fresco_bridge.cli", "lab", "integrate", "--port",
             str(bridge.ports["damper"]), "--duration", "0.5", "--connect-timeout", "10"],
            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    err = proc.stderr.strip()
    assert "LocalProtocolError" not in err and "Traceback" not in err, err
    assert err.startswith(f"error: integrator: the bridge at 127.0.0.1:{bridge.ports['damper']} "
                          "refused the session"), err
    assert "2-DOF genericClient" in err and "ctrl=(2, 2, 2, 0, 1)" in err, err
    assert "its log says why" in err and "another number of DOFs" in err, err
    assert len(err.splitlines()) == 1, err
