"""``fresco-bridge report`` on a real run with displacement correction: the section's figure,
the overview's sentence and the embedded numbers are those ``export --corrections`` writes.

The run: a compliant frame (48 kN/mm behind an 8 kN/mm specimen) on the ``rig`` controller,
corrected on its external specimen channel with gain 0.5 and at most 2 corrections a trial,
``accept-with-event``: the larger targets do not converge, so the report has both kinds."""

from __future__ import annotations

import csv
import json
import math
import re
from pathlib import Path

import pytest

from fresco_bridge.cli import main
from fresco_bridge.integrator.link import GenericClientLink
from tests.bridge.sites.test_site_correction import lab
from tests.support.bridge import RunningBridge

CORRECTION = """tolerance = 0.01
max_correction = 3.0
max_iterations = 2
gain = 0.5
policy = "accept-with-event"
measured = "external"
"""
TARGETS = [6.0 * math.sin(2 * math.pi * i / 30) for i in range(1, 61)]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("corrected")
    with RunningBridge(lab(tmp, CORRECTION), tmp / "runs") as b, \
            GenericClientLink("127.0.0.1", b.ports["frame"], 1, timeout=30.0) as link:
        for i, t in enumerate(TARGETS, 1):
            link.set_trial((t,), time=0.01 * i)
            link.force()
            link.commit()
        return b.run_dir


def test_the_report_shows_what_export_corrections_gives(run_dir: Path, tmp_path: Path) -> None:
    out, csv_path = tmp_path / "report.html", tmp_path / "corrections.csv"
    assert main(["report", str(run_dir), "-o", str(out)]) == 0
    assert main(["export", str(run_dir), "--corrections", "-o", str(csv_path)]) == 0
    with csv_path.open() as fh:
        rows = list(csv.DictReader(fh))
    trials: dict[int, dict[str, str]] = {}
    for r in rows:  # one row per command; the trial's own figures repeat on each
        trials[int(r["step"])] = r
    corrections = [int(r["corrections"]) for r in trials.values()]
    residual = [float(r["residual"]) for r in trials.values()]
    not_converged = sum(r["outcome"] != "converged" for r in trials.values())
    assert 0 < not_converged < len(trials) and max(corrections) == 2  # both kinds are shown

    text = out.read_text()
    data = json.loads(re.search(r'id="summary-data">(.*?)</script>', text, re.S)[1])
    d = data["correction"]["frame"]
    assert d["steps"] == list(trials) and d["corrections"] == corrections
    assert d["residual_mm"] == residual
    assert d["max_corrections"] == 2 and d["not_converged"] == not_converged
    assert d["median_corrections"] == sorted(corrections)[len(corrections) // 2]
    assert d["max_residual_mm"] == max(residual)
    assert d["tolerance_mm"] == 0.01 and d["max_iterations"] == 2
    assert data["overview"]["correction"]["frame"]["not_converged"] == not_converged
    section = text[text.index('id="correction-frame"'):]
    assert "data:image/png;base64," in section[:section.index("</section>")]
    glance = text[text.index('id="overview"'):text.index('id="summary"')]
    assert (f"frame: {len(trials)} trial(s) corrected, median {d['median_corrections']} and max "
            f"2 correction(s) of max_iterations 2; {not_converged} not converged") in glance
    assert "ended outside the correction's tolerance" in glance


def test_a_run_without_correction_has_no_such_section(tmp_path: Path) -> None:
    with RunningBridge(lab(tmp_path, None), tmp_path / "runs") as b, \
            GenericClientLink("127.0.0.1", b.ports["frame"], 1, timeout=30.0) as link:
        link.set_trial((1.0,), time=0.01)
        link.force()
        link.commit()
        run_dir = b.run_dir
    out = tmp_path / "report.html"
    assert main(["report", str(run_dir), "-o", str(out)]) == 0
    text = out.read_text()
    assert 'id="correction-' not in text and "displacement correction" not in text
    data = json.loads(re.search(r'id="summary-data">(.*?)</script>', text, re.S)[1])
    assert data["correction"] == {} and "correction" not in data["overview"]


def test_the_hdf5_export_holds_what_export_corrections_gives(run_dir: Path,
                                                             tmp_path: Path) -> None:
    import h5py  # type: ignore[import-untyped]

    out, csv_path = tmp_path / "run.h5", tmp_path / "corrections.csv"
    assert main(["export", str(run_dir), "-o", str(out)]) == 0
    assert main(["export", str(run_dir), "--corrections", "-o", str(csv_path)]) == 0
    with csv_path.open() as fh:
        rows = list(csv.DictReader(fh))
    with h5py.File(out, "r") as f:
        g = f["sites/frame/correction"]
        trial, iteration = g["trial"][()], g["iteration"][()]
        command, measured = g["command"][()][:, 0], g["measured"][()][:, 0]
        step, target = g["step"][()], g["target"][()][:, 0]
        outcome = [o.decode() for o in g["outcome"][()]]
        corrections, residual = g["corrections"][()], g["residual"][()]
        assert g["command"].attrs["units"] == "mm" and g["residual"].attrs["units"] == "mm"
    assert len(rows) == trial.size and step.size == len(TARGETS)
    for r, t, k, c, m in zip(rows, trial, iteration, command, measured, strict=True):
        assert (int(r["step"]), int(r["iteration"])) == (int(step[t]), int(k))
        assert (float(r["command"]), float(r["measured"])) == (c, m)
        assert float(r["target"]) == target[t] and r["outcome"] == outcome[t]
        assert (int(r["corrections"]), float(r["residual"])) == (corrections[t], residual[t])
