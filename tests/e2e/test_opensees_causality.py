"""Causality under the integrators labs use, through real OpenSeesPy over TCP: explicit
Newmark (γ = ½, β = 0) and ``CentralDifference`` with ``Linear`` (one trial per step), and
Newmark (½, ¼) with ``Newton`` (several trials per step). ``previous-step`` learns committed
steps only, whatever the scheme (equal to the in-process lagged replay); ``same-step`` learns
the source's step before answering it under the explicit schemes (equal to the in-process
replay in that order, no fallback, no mismatch), and under Newton falls back once with the
true reason, its update lines then saying previous-step."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fresco_bridge.runs import load_run
from fresco_bridge.updating.histories import read_history
from fresco_bridge.updating.registry import make_updater
from fresco_bridge.updating.replay import replay
from tests.e2e.test_opensees_updatable import NSTEPS, frame_toml, run_frame

SCHEMES: dict[str, dict[str, Any]] = {
    "explicit-newmark": {"integrator": ["NewmarkExplicit", 0.5], "algorithm": ["Linear"]},
    "central-difference": {"integrator": ["CentralDifference"], "algorithm": ["Linear"]},
    "newmark-newton": {"integrator": ["Newmark", 0.5, 0.25], "algorithm": ["Newton"]},
}


def _events(run_dir: Path, *kinds: str) -> list[dict[str, Any]]:
    return [e for e in load_run(run_dir).events if e["event"] in kinds]


def _served(tmp_path: Path, causality: str, scheme: str) -> tuple[Path, Any, Any]:
    pytest.importorskip("filterpy")
    toml = frame_toml(f'updater = "online_ukf"\ncausality = "{causality}"\n')
    served, run_dir = run_frame(toml, tmp_path, **SCHEMES[scheme])
    assert all(np.isfinite(served["u3"]))
    source, twin = read_history(run_dir, site="story1"), read_history(run_dir, site="story2")
    assert twin.force is not None and twin.disp.size == NSTEPS
    return run_dir, source, twin


def _close(a: Any, b: Any) -> bool:
    return float(np.max(np.abs(a - b))) / float(np.max(np.abs(b))) < 1e-9


@pytest.mark.parametrize("scheme", list(SCHEMES))
def test_previous_step_learns_committed_steps_only(tmp_path: Path, scheme: str) -> None:
    run_dir, source, twin = _served(tmp_path, "previous-step", scheme)
    expected = replay(make_updater("online_ukf"), source.disp, source.force, twin.disp,
                      lag=True).force_pred
    assert _close(twin.force, expected)
    assert not _events(run_dir, "same-step-fallback", "same-step-mismatch")


@pytest.mark.parametrize("scheme", ["explicit-newmark", "central-difference"])
def test_same_step_under_explicit_schemes(tmp_path: Path, scheme: str) -> None:
    run_dir, source, twin = _served(tmp_path, "same-step", scheme)
    expected = replay(make_updater("online_ukf"), source.disp, source.force, twin.disp,
                      lag=False).force_pred
    assert _close(twin.force, expected)
    assert not _events(run_dir, "same-step-fallback", "same-step-mismatch")
    updates = load_run(run_dir).updates
    assert [(u["step"], u["through"]) for u in updates][-3:] == [
        (NSTEPS - 2, NSTEPS - 2), (NSTEPS - 1, NSTEPS - 1), (NSTEPS, NSTEPS)]


def test_same_step_under_newton_falls_back_once_with_the_true_reason(tmp_path: Path) -> None:
    run_dir, _, _ = _served(tmp_path, "same-step", "newmark-newton")
    (fallback,) = _events(run_dir, "same-step-fallback")
    assert "several trials" in fallback["reason"] and "implicit" in fallback["reason"]
    assert len(_events(run_dir, "same-step-mismatch")) <= 1  # at most the first step's
    updates = load_run(run_dir).updates
    assert all(u["through"] == u["step"] - 1 for u in updates[5:])  # previous-step, said
