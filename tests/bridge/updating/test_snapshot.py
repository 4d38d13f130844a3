"""Updater snapshots: ``snapshot`` then ``restore`` mid-run gives an updater (and twin) that
continues exactly as the uninterrupted one, for every updater of the registry; bad bytes are a
clear error."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from fresco_bridge.updating import UpdaterError, make_updater, restore, snapshot
from fresco_bridge.updating.ann import AnnModel
from tests.support.histories import disp_history, force_history


def _updaters(small_ann: AnnModel) -> dict[str, Any]:
    d = disp_history(400, seed=5, amp=3.0)
    offline = (d, force_history(d))
    return {
        "none": make_updater("none", offline=offline),
        "online_ukf": make_updater("online_ukf", offline=offline),
        "online_ann": make_updater("online_ann", model=small_ann, offline_samples=50,
                                   window=20, max_iterations=2),
        "online_improved": make_updater("online_improved", offline=offline),
    }


def _drive(updater: Any, d: np.ndarray, f: np.ndarray) -> np.ndarray:
    out = np.empty(d.size)
    for i in range(d.size):
        updater.observe(float(d[i]), float(f[i]))
        out[i] = updater.twin.set_trial(0.8 * float(d[i]))[0]
        updater.twin.commit()
    return out


@pytest.mark.parametrize("name", ["none", "online_ukf", "online_ann", "online_improved"])
def test_a_restored_updater_continues_exactly(name: str, small_ann: AnnModel) -> None:
    updater = _updaters(small_ann)[name]
    d = disp_history(700, seed=9, amp=4.0)
    f = force_history(d)
    _drive(updater, d[:380], f[:380])  # past the first refits of online_improved's laws
    blob = snapshot(updater)
    copy = restore(blob)
    assert copy is not updater and copy.name == updater.name
    np.testing.assert_array_equal(_drive(copy, d[380:], f[380:]),
                                  _drive(updater, d[380:], f[380:]))


def test_bad_snapshots_are_clear_errors() -> None:
    with pytest.raises(UpdaterError, match="not an updater snapshot"):
        restore(b"hello")
    blob = snapshot(make_updater("none"))
    with pytest.raises(UpdaterError, match="truncated or corrupted"):
        restore(blob[:-5])
    with pytest.raises(UpdaterError, match="cannot be snapshot"):
        snapshot(type("Gen", (), {"name": "gen", "g": (i for i in range(2))})())  # type: ignore[arg-type]
