"""ANN model files: round trip, and clear errors for files that are not ours or not this spec."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from fresco_bridge.updating import UpdaterError, make_updater
from fresco_bridge.updating.ann import AnnModel
from fresco_bridge.updating.modelfile import load_model, save_model

torch = pytest.importorskip("torch")


def test_round_trip_is_exact(small_ann: AnnModel, tmp_path: Path) -> None:
    path = tmp_path / "damper.pt"
    save_model(small_ann, path)
    back = load_model(path)
    np.testing.assert_array_equal(back.theta, small_ann.theta)
    np.testing.assert_array_equal(back.scaler.x_min, small_ann.scaler.x_min)
    np.testing.assert_array_equal(back.scaler.x_range, small_ann.scaler.x_range)
    assert (back.scaler.y_min, back.scaler.y_range) == (small_ann.scaler.y_min,
                                                        small_ann.scaler.y_range)
    np.testing.assert_array_equal(back.offline_force, small_ann.offline_force)
    assert back.spec == small_ann.spec and back.net.layers == small_ann.net.layers
    assert back.training["iterations"] == small_ann.training["iterations"]
    d = small_ann.offline_d
    np.testing.assert_array_equal(back.simulate(d), small_ann.simulate(d))
    u = make_updater("offline_ann", model_file=path)
    assert u.twin.set_trial(1.0) == make_updater("offline_ann", model=small_ann).twin.set_trial(1.0)
    assert not list(tmp_path.glob(".*.tmp"))  # written atomically


def test_file_is_a_torch_sequential(small_ann: AnnModel, tmp_path: Path) -> None:
    """The state dict loads into nn.Sequential(Linear, Tanh, ...) and predicts the same."""
    path = tmp_path / "m.pt"
    save_model(small_ann, path)
    data = torch.load(path, weights_only=True)
    layers = data["layers"]
    mods: list[torch.nn.Module] = []
    for i, (n_in, n_out) in enumerate(itertools.pairwise(layers)):
        mods.append(torch.nn.Linear(n_in, n_out, dtype=torch.float64))
        if i < len(layers) - 2:
            mods.append(torch.nn.Tanh())
    seq = torch.nn.Sequential(*mods)
    seq.load_state_dict(data["state_dict"])
    x = np.random.default_rng(0).random((5, 6))
    with torch.no_grad():
        out = seq(torch.from_numpy(x)).numpy()[:, 0]
    np.testing.assert_allclose(out, small_ann.net.forward(small_ann.theta, x), rtol=1e-12)


def _rewrite(path: Path, **changes: object) -> None:
    data = torch.load(path, weights_only=True)
    data.update(changes)
    torch.save(data, path)


def test_other_feature_spec_is_a_clear_error(small_ann: AnnModel, tmp_path: Path) -> None:
    path = tmp_path / "other.pt"
    save_model(small_ann, path)
    spec = {"name": "kim5", "version": 1, "inputs": ["d_i", "d_im1", "F_im1", "x", "y"],
            "output": "F_i"}
    _rewrite(path, feature_spec=spec)
    with pytest.raises(UpdaterError, match=rf"{path}: feature spec 'kim5' v1 .* not the one"):
        load_model(path)
    with pytest.raises(UpdaterError, match="feature spec 'kim5'"):
        make_updater("online_ann", model_file=path)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"format": "something-else"}, "not a fresco-bridge model file"),
        ({"version": 99}, "version 99 is newer"),
        ({"layers": [6, 10, 1]}, "shapes"),
        ({"activation": "relu"}, "activation 'relu'"),
    ],
)
def test_damaged_files_are_clear_errors(small_ann: AnnModel, tmp_path: Path,
                                        change: dict[str, object], message: str) -> None:
    path = tmp_path / "bad.pt"
    save_model(small_ann, path)
    _rewrite(path, **change)
    with pytest.raises(UpdaterError, match=message):
        load_model(path)


def test_not_a_model_file(tmp_path: Path) -> None:
    junk = tmp_path / "junk.pt"
    junk.write_text("time,disp,force\n")
    with pytest.raises(UpdaterError, match=rf"{junk}: not a"):
        load_model(junk)
    with pytest.raises(UpdaterError, match="no such model file"):
        load_model(tmp_path / "missing.pt")
