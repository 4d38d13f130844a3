"""``updater replay|pretrain`` read what the bridge writes: its run directory and its export CSV.

A real bridge records a run with two sites (a simulated spring with two integrator sessions, and
the simulated lab whose LVDT reads with noise, so its measured displacement is not the command);
the commands read it directly or through ``fresco-bridge export``, pick a site and a session,
and learn from the measured displacement. An updater missing what it is built from, or given a
bad ``--option``, is one line on stderr naming the option, exit 2, no traceback.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fresco_bridge.cli import main
from fresco_bridge.updating.modelfile import load_model
from fresco_bridge.updating.registry import UPDATERS
from tests.support.recorded_run import LAB_TOML, record_sessions, rig_site

SESSIONS = [("spring", 40), ("spring", 25), ("rig", 60)]


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("two_sites")
    toml = LAB_TOML.format(name="two", telemetry="") + rig_site(root)
    run_dir = record_sessions(root / "runs", toml, SESSIONS)
    export = root / "export.csv"
    assert main(["export", str(run_dir), "-o", str(export)]) == 0
    return {"dir": run_dir, "export": export, "root": root}


def _export_rows(path: Path, site: str) -> list[dict[str, str]]:
    with path.open() as fh:
        return [r for r in csv.DictReader(fh) if r["site"] == site]


def _plain_csv(path: Path, rows: list[dict[str, str]], disp: str) -> Path:
    """``time,disp,force`` from export rows, ``disp`` taken from the column named."""
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time", "disp", "force"])
        w.writerows([r["time"], r[disp], r["meas_force"]] for r in rows)
    return path


def _replay(capsys: pytest.CaptureFixture[str], out: Path, source: Path, twin: Path,
            *extra: str) -> tuple[int, str, dict[str, Any], list[float]]:
    """(exit code, stderr, the JSON summary, the predictions) of an ``online_ukf`` replay."""
    code = main(["updater", "replay", "--source", str(source), "--twin", str(twin),
                 "--updater", "online_ukf", "--quiet", "-o", str(out), *extra])
    err = capsys.readouterr().err
    if code != 0:
        return code, err, {}, []
    with out.open() as fh:
        pred = [float(r["force_pred"]) for r in csv.DictReader(fh)]
    return code, err, json.loads(out.with_suffix(".json").read_text()), pred


def test_export_run_directory_and_plain_csv_replay_alike_on_the_measured_displacement(
    run: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    rows = _export_rows(run["export"], "rig")
    meas = np.array([float(r["meas_disp"]) for r in rows])
    cmd = np.array([float(r["cmd_disp"]) for r in rows])
    assert len(rows) == 60 and np.max(np.abs(meas - cmd)) > 0.01  # the LVDT's noise
    root = run["root"]
    measured = _plain_csv(root / "meas.csv", rows, "meas_disp")
    commanded = _plain_csv(root / "cmd.csv", rows, "cmd_disp")
    preds = {}
    for name, data, extra in (("export", run["export"], ["--site", "rig"]),
                              ("dir", run["dir"], ["--site", "rig"]),
                              ("meas", measured, []), ("cmd", commanded, [])):
        code, err, summary, preds[name] = _replay(capsys, root / f"pred_{name}.csv", data, data,
                                                  *extra)
        assert code == 0, err
        assert summary["steps"] == 60
    assert preds["export"] == preds["dir"] == preds["meas"]
    assert preds["cmd"] != preds["meas"]
    summary = json.loads((root / "pred_dir.json").read_text())
    assert summary["source"] == f"{run['dir']} (site rig, session 1, actuator 1)"


@pytest.mark.parametrize("kind", ["dir", "export"])
def test_several_sites_need_site_and_the_error_lists_them(
    run: dict[str, Path], capsys: pytest.CaptureFixture[str], kind: str
) -> None:
    out = run["root"] / f"ambiguous_{kind}.csv"
    code, err, _, _ = _replay(capsys, out, run[kind], run[kind])
    assert code == 2 and not out.exists()
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"error: {run[kind]}: the record holds 2 sites (rig, spring); "
                          "choose one with --site")


def test_site_and_session_choose_what_is_replayed(
    run: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """The last session by default (said on stderr), --session for another, --twin-site for a
    twin that is another site of the run; unknown site or session: one line, exit 2."""
    out = run["root"] / "sessions.csv"
    main(["updater", "replay", "--source", str(run["export"]), "--twin", str(run["export"]),
          "--site", "spring", "--updater", "none", "--quiet", "-o", str(out)])
    captured = capsys.readouterr()
    assert "source: 2 integrator sessions: the last (session 2, 25 steps) used" in captured.err
    assert json.loads(out.with_suffix(".json").read_text())["steps"] == 25
    code, err, summary, _ = _replay(capsys, out, run["dir"], run["dir"], "--site", "rig",
                                    "--session", "1", "--twin-site", "spring")
    assert code == 0 and summary["steps"] == 40, err  # spring's first session
    assert summary["twin"] == f"{run['dir']} (site spring, session 1, actuator 1)"
    code, err, _, _ = _replay(capsys, out, run["dir"], run["dir"], "--site", "spring",
                              "--session", "1", "--twin-site", "rig")
    assert code == 2 and "60 steps, but" in err and "has only 40" in err, err
    for extra, fragment in ((["--site", "nope"], "no site 'nope' in the record (sites: rig, "
                                                 "spring)"),
                            (["--site", "spring", "--session", "7"],
                             "(site spring) has sessions 1, 2, not 7")):
        code, err, _, _ = _replay(capsys, run["root"] / "bad.csv", run["export"], run["export"],
                                  *extra)
        assert code == 2 and err.count("\n") == 1 and fragment in err, err


def test_pretrain_reads_the_export_as_the_run_directory(run: dict[str, Path],
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    models = {}
    for kind in ("dir", "export"):
        out = run["root"] / f"{kind}.pt"
        assert main(["updater", "pretrain", str(run[kind]), "--site", "rig", "-o", str(out),
                     "--iterations", "2", "--no-plot"]) == 0
        models[kind] = load_model(out)
    assert np.array_equal(models["dir"].offline_d, models["export"].offline_d)
    assert np.array_equal(models["dir"].offline_force, models["export"].offline_force)
    meas = [float(r["meas_disp"]) for r in _export_rows(run["export"], "rig")]
    assert models["export"].offline_d.tolist() == meas
    capsys.readouterr()


_ANN = ("needs --model F (a network from `updater pretrain`) or --offline DATA (an earlier "
        "history of the tested element)")
NEEDS = {"offline_ann": _ANN, "online_ann": _ANN,
         "online_improved": "needs --offline DATA (an earlier history of the tested element)"}


@pytest.mark.parametrize("name", sorted(UPDATERS))
def test_an_updater_without_what_it_is_built_from_names_the_option(
    run: dict[str, Path], capsys: pytest.CaptureFixture[str], name: str
) -> None:
    """Every updater without --model/--offline: it runs (it has defaults) or says which flag."""
    out = run["root"] / f"bare_{name}.csv"
    code = main(["updater", "replay", "--source", str(run["dir"]), "--twin", str(run["dir"]),
                 "--site", "rig", "--updater", name, "--quiet", "-o", str(out)])
    err = capsys.readouterr().err
    if name in NEEDS:
        assert code == 2 and not out.exists()
        assert err == f"error: updater {name!r} {NEEDS[name]}\n"
    else:
        assert code == 0, err
        assert out.exists()


@pytest.mark.parametrize(("name", "option", "fragment"), [
    ("online_ann", "seed=1.5", "--option seed=1.5: updater 'online_ann' takes an integer for seed"),
    ("online_ukf", 'k0="a"', "--option k0=\"a\": updater 'online_ukf' takes a number or null "
                             "for k0"),
    ("none", "params=3", "--option params=3: updater 'none' takes an object of numbers or null "
                         "for params"),
    ("online_improved", "law_trust=\"yes\"", "takes a number for law_trust"),
    ("online_improved", "experts=3", "takes a string or a list of strings for experts"),
    ("online_ukf", "offline=1", "--option offline: give it as --offline DATA"),
    ("online_ann", "model_file=\"m.pt\"", "--option model_file: give it as --model F"),
    ("online_ukf", "bogus=1", "updater 'online_ukf': unknown option(s) bogus; allowed: k0,"),
    ("online_ukf", "q=[1,2]", "online_ukf: q must be one or three positive finite numbers"),
    ("online_ukf", 'p0="abc"', "updater 'online_ukf': an --option value was refused "
                               "(p0=\"abc\"): could not convert string to float: 'abc'"),
])
def test_a_bad_option_is_one_line_naming_it(
    run: dict[str, Path], capsys: pytest.CaptureFixture[str], name: str, option: str,
    fragment: str
) -> None:
    out = run["root"] / "bad_option.csv"
    extra = ["--offline", str(run["export"]), "--offline-site", "spring"] \
        if name in NEEDS and "model_file" not in option else []
    code = main(["updater", "replay", "--source", str(run["export"]), "--twin",
                 str(run["export"]), "--site", "rig", "--updater", name, "--option", option,
                 *extra, "--quiet", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and not out.exists()
    assert err.startswith("error: ") and err.count("\n") == 1 and fragment in err, err
