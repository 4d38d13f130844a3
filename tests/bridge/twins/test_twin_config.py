"""Bad updatable-site configs: each error names the file, the key and the reason."""

from __future__ import annotations

from pathlib import Path

import pytest

from fresco_bridge.config import ConfigError, load_config

SOURCE = '[[sites]]\nname = "damper"\nport = 0\n'
TWO_ACTUATORS = '[[sites]]\nname = "damper"\nport = 0\ndofs = 2\n'


def twin(**keys: str) -> str:
    body = {"learns_from": '"damper"', "updater": '"online_ukf"', **keys}
    return ('[[sites]]\nname = "twin1"\nport = 0\nkind = "updatable"\n'
            + "".join(f"{k} = {v}\n" for k, v in body.items()))


def error_of(tmp_path: Path, text: str) -> str:
    path = tmp_path / "lab.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as exc:
        load_config(path)
    message = str(exc.value)
    assert message.startswith(f"{path}: ") and "Traceback" not in message
    return message


@pytest.mark.parametrize(("text", "key", "reason"), [
    (SOURCE + twin(learns_from='"nosuch"'), "sites[1].learns_from", "no site named 'nosuch'"),
    (SOURCE + twin() + twin().replace('"twin1"', '"twin2"').replace('"damper"', '"twin1"'),
     "sites[2].learns_from", "site 'twin1' is updatable"),
    (TWO_ACTUATORS + twin(), "sites[1].learns_from", "drives 2 actuators"),
    (SOURCE + twin(updater='"magic"'), "sites[1].updater", "unknown updater 'magic'"),
    (SOURCE + twin(updater='"online_improved"'), "sites[1].updater",
     "needs offline"),
    (SOURCE + twin(updater='"online_ann"'), "sites[1].updater", "needs offline"),
    (SOURCE + twin(offline='"missing.csv"'), "sites[1].offline", "missing.csv"),
    (SOURCE + twin(causality='"same-step"', learner_deadline="2.5"),
     "sites[1].learner_deadline", "twice it must be shorter"),
    (SOURCE + twin() + "[sites.updater_options]\nwobble = 1\n", "sites[1].updater_options",
     "unknown option(s) wobble"),
    (SOURCE + twin(learner_deadline="9.0"), "sites[1].learner_deadline",
     "shorter than bridge.controller_timeout"),
    (SOURCE + twin() + '[sites.controller]\nmodel = "bilinear"\n', "sites[1].controller",
     "a key of kind = \"experimental\" sites (this site is updatable"),
    (SOURCE.replace("port = 0\n", 'port = 0\nupdater = "none"\n'), "sites[0].updater",
     "a key of kind = \"updatable\" sites (this site is experimental"),
    (SOURCE + twin().replace('"updatable"', '"updateable"'), "sites[1]",
     "unknown site kind 'updateable'; expected experimental or updatable"),
])
def test_bad_updatable_site(tmp_path: Path, text: str, key: str, reason: str) -> None:
    message = error_of(tmp_path, text)
    line = next((ln for ln in message.splitlines()  # after "line N, site NAME: " when known
                 if ln.strip().startswith(f"{key}:") or f": {key}:" in ln), None)
    assert line is not None and reason in line, message


def test_a_model_file_of_another_feature_spec(tmp_path: Path) -> None:
    pytest.importorskip("torch")
    from fresco_bridge.updating.ann import pretrain
    from fresco_bridge.updating.modelfile import save_model
    from tests.bridge.twins.test_worker import histories

    d, f, _ = histories(40)
    model = pretrain(d, f, seed=0, source="test")
    path = tmp_path / "damper.pt"
    save_model(model, path)
    import torch

    data = torch.load(path, weights_only=True)
    data["feature_spec"] = {"name": "other", "inputs": ["d"]}
    torch.save(data, path)
    message = error_of(tmp_path, SOURCE + twin(updater='"offline_ann"', model='"damper.pt"'))
    assert "sites[1].model:" in message and "damper.pt" in message


def test_relative_data_paths_resolve_against_the_config_folder(tmp_path: Path) -> None:
    (tmp_path / "char.csv").write_text("time,disp,force\n0.01,0.1,1.0\n0.02,0.2,2.0\n")
    path = tmp_path / "lab.toml"
    path.write_text(SOURCE + twin(offline='"char.csv"'))
    cfg, _ = load_config(path)
    assert cfg.sites[1].offline == tmp_path / "char.csv"
