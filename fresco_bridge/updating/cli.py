"""``fresco-bridge updater pretrain|replay``: parser and handler (registered in the CLI).

* ``pretrain DATA -o model.pt`` — the paper's Step 1-2: an ANN trained on existing test data,
  a fit plot beside the model file.
* ``replay --source SRC --twin TWIN --updater NAME -o pred.csv`` — any updater on archived
  data: SRC is the tested element step by step, TWIN the twin's displacement (and its force
  when known, for scoring). Writes ``step,disp,force_pred[,force_true]`` and a JSON summary
  beside it, prints MAETH / RMS / peak errors.

Every history (DATA, SRC, TWIN, ``--offline``) is a bridge run directory, the bridge's export
CSV or a ``time,disp,force`` CSV, read by :func:`.histories.read_history` (the measured
displacement). Bad input (files, columns, options) is one line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import csv
import inspect
import json
import sys
import time
import types
import typing
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..numbers import fmt
from ..progress import status
from .base import UpdaterError
from .histories import History, HistoryError, Units, read_history, updatable_site
from .registry import UPDATERS, make_updater, updater_options

__all__ = ["add_updater_parser", "updater_command"]


def _units(text: str) -> Units:
    try:
        return Units.parse(text)
    except HistoryError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _hidden(text: str) -> tuple[int, ...]:
    try:
        sizes = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected sizes like 10,10,10, got {text!r}") from None
    if not sizes or any(n < 1 for n in sizes):
        raise argparse.ArgumentTypeError(f"hidden layer sizes must be >= 1, got {text!r}")
    return sizes


def parse_option(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` (VALUE as JSON, else a bare string) for ``--option`` arguments."""
    key, sep, raw = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    try:
        value = json.loads(raw)
    except json.JSONDecodeError:
        value = raw  # a bare word: a string option (e.g. model=bwbn)
    if isinstance(value, list):
        value = tuple(value)
    return key.strip(), value


def add_updater_parser(sub: Any) -> None:
    """``updater pretrain`` and ``updater replay``."""
    p_up = sub.add_parser("updater", help="online model updating: pre-train an ANN, replay an "
                                          "updater on recorded data")
    cmds = p_up.add_subparsers(dest="updater_command", required=True)
    p = cmds.add_parser(
        "pretrain", help="train the paper's ANN on existing test data (Step 1-2)",
        description="Train the source paper's restoring-force network (6 -> 10 x 3 tanh -> 1) "
                    "on the tested element's measured (d, F) history by Levenberg-Marquardt and "
                    "write a versioned model file (torch format) and a fit plot.")
    p.add_argument("data", type=Path, metavar="DATA", help=_DATA_HELP)
    p.add_argument("-o", "--out", type=Path, required=True, help="model file to write (.pt)")
    p.add_argument("--site", default=None,
                   help="site of a run directory or export (default: its only one)")
    p.add_argument("--actuator", type=int, default=1, help="actuator of the site (default 1)")
    p.add_argument("--session", type=int, default=None,
                   help="integrator session of a run directory or export (default: the last)")
    p.add_argument("--samples", type=int, default=None,
                   help="use the first N steps (the paper: 2500; default: all)")
    p.add_argument("--iterations", type=int, default=1000,
                   help="LM iterations (default 1000, MATLAB trainlm's epochs)")
    p.add_argument("--hidden", type=_hidden, default=(10, 10, 10),
                   help="hidden layer sizes (default 10,10,10: the paper's 301 parameters)")
    p.add_argument("--seed", type=int, default=0, help="weight initialisation seed (default 0)")
    p.add_argument("--units", type=_units, default=Units(), metavar="DISP,FORCE",
                   help="units of a CSV's disp and force (default mm,kN)")
    p.add_argument("--plot", type=Path, default=None,
                   help="fit plot PNG (default: the model file with .png)")
    p.add_argument("--no-plot", action="store_true", help="do not draw the fit plot")

    r = cmds.add_parser(
        "replay", help="evaluate an updater offline on recorded data",
        description="Step through SRC (the tested element's displacement and force) and TWIN "
                    "(the twin's displacement, and its force when known) row by row: the "
                    "updater observes SRC step i and the twin predicts its force at TWIN's "
                    "displacement of step i (with --lag, before observing step i). Writes "
                    "step,disp,force_pred[,force_true]. " + _DATA_HELP)
    r.add_argument("--source", type=Path, required=True, metavar="SRC",
                   help="the tested element's history")
    r.add_argument("--twin", type=Path, required=True, metavar="TWIN",
                   help="the twin's history (a force column, when present, is scored against)")
    r.add_argument("--updater", required=True, choices=sorted(UPDATERS),
                   help="; ".join(f"{k}: {v.description}" for k, v in UPDATERS.items()))
    r.add_argument("--model", type=Path, default=None, metavar="F",
                   help="ANN model file from `updater pretrain` (offline_ann, online_ann)")
    r.add_argument("--offline", type=Path, default=None, metavar="DATA",
                   help="offline database (an earlier test of the element): the start of "
                        "online_improved and online_ukf, the calibrated Bilinear of none; the "
                        "ANN is pre-trained on it in process (instead of --model)")
    r.add_argument("--site", default=None,
                   help="site of SRC and TWIN when a run directory or export holds several")
    r.add_argument("--twin-site", default=None, metavar="SITE",
                   help="TWIN's site when it is another site of the run (default: --site)")
    r.add_argument("--offline-site", default=None, metavar="SITE",
                   help="site of --offline when it holds several")
    r.add_argument("--session", type=int, default=None,
                   help="integrator session of SRC and TWIN (default: the last of each)")
    r.add_argument("--actuator", type=int, default=1,
                   help="actuator of a multi-actuator site (default 1)")
    r.add_argument("--lag", action="store_true",
                   help="the twin's step i only knows the source through step i-1")
    r.add_argument("--option", type=parse_option, action="append", default=[], metavar="KEY=VALUE",
                   help="an updater option (JSON value), repeatable, e.g. max_iterations=50")
    r.add_argument("--units", type=_units, default=Units(), metavar="DISP,FORCE",
                   help="units of the CSVs' disp and force (a run directory is in mm,kN), "
                        "also used for pred.csv (default mm,kN)")
    r.add_argument("-o", "--out", type=Path, required=True, help="predictions CSV to write")
    r.add_argument("--quiet", action="store_true", help="no progress bar")


def updater_command(args: argparse.Namespace) -> int:
    """Run ``updater pretrain|replay``; bad input -> one line on stderr, exit 2."""
    try:
        if args.updater_command == "pretrain":
            return _pretrain(args)
        return _replay(args)
    except UpdaterError as exc:  # HistoryError included
        print(f"error: {exc}", file=sys.stderr)
        return 2


_DATA_HELP = ("A history is a bridge run directory, the bridge's export CSV (`fresco-bridge "
              "export`: an updater learns from meas_disp, the displacement the specimen went "
              "through, not cmd_disp) or a CSV with columns time,disp,force.")


def _load_training_data(args: argparse.Namespace) -> tuple[np.ndarray, np.ndarray, str]:
    history = read_history(args.data, site=args.site, session=args.session,
                           actuator=args.actuator, units=args.units)
    assert history.force is not None  # need_force
    _print_notes("data", history)
    return history.disp, history.force, history.source


def _print_notes(role: str, history: History) -> None:
    for note in history.notes:
        print(f"{role}: {note}", file=sys.stderr)


def _pretrain(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from fresco_bridge import indicators
    from fresco_bridge.progress import ProgressBar

    from .ann import PRETRAIN_LM, pretrain, recurrence_warning
    from .modelfile import import_torch, save_model

    if args.iterations < 1:
        raise UpdaterError(f"--iterations must be >= 1, got {args.iterations}")
    status(f"pretrain: loading torch, reading {args.data}")
    import_torch("writing a model file")  # fail before a long training, not after it
    disp, force, source = _load_training_data(args)
    if args.samples is not None:
        if args.samples < 2:
            raise UpdaterError(f"--samples must be >= 2, got {args.samples}")
        disp, force = disp[: args.samples], force[: args.samples]
    print(f"pretrain: {len(disp)} samples from {source}; network "
          f"6-{'-'.join(map(str, args.hidden))}-1, LM up to {args.iterations} iterations",
          flush=True)
    start = time.perf_counter()
    with ProgressBar("pretrain", args.iterations) as bar:
        model = pretrain(disp, force, layers=(6, *args.hidden, 1), seed=args.seed,
                         options=replace(PRETRAIN_LM, max_iterations=args.iterations),
                         progress=bar, source=source)
        bar(args.iterations, args.iterations)
    seconds = time.perf_counter() - start
    model.training["seconds"] = seconds
    one_step = model.predict_one_step(disp, force)
    free_run = model.simulate(disp)
    model.training["one_step_rmse_kN"] = indicators.one_step_rmse(force, one_step)
    model.training["free_run_maeth_kN"] = indicators.maeth(force, free_run)
    save_model(model, args.out)
    t = model.training
    print(f"wrote {args.out}: {model.net.n_params} parameters, {t['iterations']} iterations "
          f"({t['stop']}), {seconds:.1f} s; normalised MSE "
          f"{fmt(t['mse_normalised'], digits=3)}; "
          f"one-step RMSE {fmt(t['one_step_rmse_kN'])} kN, free-run MAETH "
          f"{fmt(t['free_run_maeth_kN'])} kN (the twin's own recurrence on the training data)")
    warning = recurrence_warning(t["free_run_maeth_kN"], float(np.max(np.abs(force))))
    if warning is not None:
        print(warning, file=sys.stderr)
    if not args.no_plot:
        plot = args.plot if args.plot is not None else args.out.with_suffix(".png")
        _fit_plot(plot, disp, force, one_step, free_run, source)
        print(f"wrote {plot}")
    return 0


def _fit_plot(path: Path, disp: np.ndarray, force: np.ndarray, one_step: np.ndarray,
              free_run: np.ndarray, source: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.5))
    ax1.plot(disp, force, color="0.3", lw=1.2, label="measured")
    ax1.plot(disp, free_run, color="C3", lw=0.9, label="ANN, own recurrence")
    ax1.set_xlabel("displacement (mm)")
    ax1.set_ylabel("force (kN)")
    ax1.set_title("hysteresis")
    ax1.legend(loc="best", fontsize=8)
    steps = np.arange(len(force))
    ax2.plot(steps, one_step - force, color="C0", lw=0.8, label="one-step error")
    ax2.plot(steps, free_run - force, color="C3", lw=0.8, label="recurrence error")
    ax2.set_xlabel("step")
    ax2.set_ylabel("force error (kN)")
    ax2.set_title("prediction error")
    ax2.legend(loc="best", fontsize=8)
    fig.suptitle(f"pre-trained ANN on {source}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _served(path: Path, site: str | None, history: History) -> str:
    """Where a history of an updatable site's served forces comes from, and how it says so
    (a run directory's config and update lines, or an export's ``predicted`` column)."""
    if site is not None:
        return f"{path}: site {site!r} is an updatable site"
    return f"{history.source}: an updatable site's, as the export says (predicted = 1)"


def _replay(args: argparse.Namespace) -> int:
    from fresco_bridge import indicators
    from fresco_bridge.progress import ProgressBar

    from .replay import replay

    given = dict(args.option)
    _check_options(args.updater, given, model=args.model is not None,
                   offline=args.offline is not None)
    status(f"replay {args.updater}: reading {args.source} (source) and {args.twin} (twin)")
    src = read_history(args.source, site=args.site, session=args.session,
                       actuator=args.actuator, units=args.units)
    twin = read_history(args.twin, need_force=False, site=args.twin_site or args.site,
                        session=args.session, actuator=args.actuator, units=args.units)
    assert src.force is not None  # need_force
    served = updatable_site(args.source, args.site)
    if served is not None or src.predicted:
        raise HistoryError(f"{_served(args.source, served, src)}: its forces are its "
                           "updater's predictions, not measurements; give the tested element "
                           "it learns from (its learns_from site) as --source")
    served = updatable_site(args.twin, args.twin_site or args.site)
    if (served is not None or twin.predicted) and twin.force is not None:
        print(f"twin: {_served(args.twin, served, twin)}: its forces are the predictions "
              "served to the integrator, not a truth; not scored against (give --twin a "
              "history with measured or true forces to score)", file=sys.stderr)
        twin = replace(twin, force=None)
    n_src, n_twin = len(src.disp), len(twin.disp)
    if n_twin > n_src:
        raise HistoryError(f"{twin.source}: {n_twin} steps, but {src.source} has only {n_src}: "
                           "every twin step needs the source's step")
    _print_notes("source", src)
    _print_notes("twin", twin)
    options = dict(given)
    if args.model is not None:
        options["model_file"] = args.model
    if args.offline is not None:
        database = read_history(args.offline, site=args.offline_site, actuator=args.actuator,
                                units=args.units)
        _print_notes("offline", database)
        options["offline"] = (database.disp, database.force)
    updater = _build_updater(args.updater, options, given)
    start = time.perf_counter()
    with ProgressBar(f"replay {args.updater}", n_twin, enabled=not args.quiet) as bar:
        result = replay(updater, src.disp, src.force, twin.disp, lag=args.lag, progress=bar)
    wall = time.perf_counter() - start
    _write_predictions(args.out, result.twin_disp, result.force_pred, twin.force, args.units)
    summary: dict[str, Any] = {
        "updater": args.updater,
        "options": {k: _jsonable(v) for k, v in options.items() if k != "offline"},
        "offline": str(args.offline) if args.offline is not None else None,
        "source": src.source, "twin": twin.source, "lag": args.lag,
        "units": str(args.units), "steps": n_twin, "wall_seconds": wall,
        "update_ms": {"median": float(np.median(result.update_seconds) * 1e3),
                      "p99": float(np.percentile(result.update_seconds, 99) * 1e3),
                      "max": float(np.max(result.update_seconds) * 1e3)},
    }
    lines = [f"replay {args.updater}{' --lag' if args.lag else ''}: {n_twin} steps in "
             f"{fmt(wall, 's', 3)}; update median "
             f"{fmt(summary['update_ms']['median'], 'ms', 3)}, p99 "
             f"{fmt(summary['update_ms']['p99'], 'ms', 3)}"]
    if twin.force is not None:
        true = twin.force
        peaks = indicators.peak_values(true, result.force_pred)
        metrics = {
            "maeth": indicators.maeth(true, result.force_pred),
            "rms": indicators.rmseth(true, result.force_pred),
            "pv_true_pos": peaks.pv_es_pos, "pv_true_neg": peaks.pv_es_neg,
            "pv_pred_pos": peaks.pv_ums_pos, "pv_pred_neg": peaks.pv_ums_neg,
            "aepv_pos": peaks.aepv_pos, "aepv_neg": peaks.aepv_neg,
        }
        summary["metrics_kN"] = metrics
        f = 1.0 / args.units.to_kn
        unit = args.units.force
        lines.append(
            f"MAETH {fmt(metrics['maeth'] * f, unit)}, RMS error {fmt(metrics['rms'] * f, unit)}; "
            f"peaks true +{fmt(peaks.pv_es_pos * f)}/-{fmt(peaks.pv_es_neg * f)}, predicted "
            f"+{fmt(peaks.pv_ums_pos * f)}/-{fmt(peaks.pv_ums_neg * f)} {unit} (AEPV "
            f"{fmt(peaks.aepv_pos * f)}/{fmt(peaks.aepv_neg * f)} {unit})")
        offline = _offline_database(options)
        baseline = None
        if offline is not None and args.updater != "none":
            try:
                baseline = make_updater("none", offline=offline)
            except UpdaterError as exc:  # e.g. a model file's database too short to calibrate
                lines.append(f"no calibrated-Bilinear baseline: {exc}")
        if baseline is not None:
            base = replay(baseline, src.disp, src.force, twin.disp, lag=args.lag)
            base_metrics = {"maeth": indicators.maeth(true, base.force_pred),
                            "rms": indicators.rmseth(true, base.force_pred)}
            summary["baseline"] = {"updater": "none --offline (the calibrated Bilinear)",
                                   "metrics_kN": base_metrics}
            lines.append(
                f"the Bilinear calibrated to the same offline database: MAETH "
                f"{fmt(base_metrics['maeth'] * f, unit)}, RMS error "
                f"{fmt(base_metrics['rms'] * f, unit)}; {args.updater} is "
                f"{_relative(metrics['maeth'], base_metrics['maeth'])} "
                f"in MAETH, {_relative(metrics['rms'], base_metrics['rms'])} in RMS error")
    else:
        lines.append(f"{twin.source} has no force column: nothing to score against")
    meta = args.out.with_suffix(".json")
    meta.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    lines.append(f"wrote {args.out} and {meta}")
    print("\n".join(lines))
    return 0


_OPTION_FLAGS = {"model_file": "--model F (a network from `updater pretrain`)",
                 "offline": "--offline DATA (an earlier history of the tested element)"}
"""Updater options the command line gives by their own flag, not by --option."""


def _check_options(name: str, given: dict[str, Any], *, model: bool, offline: bool) -> None:
    """Before any file is read: what the updater needs, what it takes, the --option types."""
    for key in given:
        if key in _OPTION_FLAGS:
            raise UpdaterError(f"--option {key}: give it as {_OPTION_FLAGS[key]}")
    accepted = updater_options(name)
    if model and "model_file" not in accepted:
        raise UpdaterError(f"--model: updater {name!r} takes no model file")
    if offline and "offline" not in accepted:
        raise UpdaterError(f"--offline: updater {name!r} takes no offline database")
    needs = UPDATERS[name].needs
    if needs and not ((model and "model_file" in needs) or (offline and "offline" in needs)):
        flags = [flag for key, flag in _OPTION_FLAGS.items() if key in needs]
        raise UpdaterError(f"updater {name!r} needs {' or '.join(flags)}")
    factory = UPDATERS[name].load()
    hints = typing.get_type_hints(factory.__init__ if inspect.isclass(factory) else factory)
    for key, value in given.items():
        if key in hints and not _fits(value, hints[key]):
            raise UpdaterError(f"--option {key}={json.dumps(_jsonable(value))}: updater "
                               f"{name!r} takes {_kind(hints[key])} for {key}")


def _fits(value: Any, hint: Any) -> bool:
    """Whether a JSON-decoded ``--option`` value fits a factory's annotation (unknown: yes)."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is Any:
        return True
    if origin in (typing.Union, types.UnionType):
        return any(_fits(value, a) for a in args)
    if hint in (int, float) and isinstance(value, bool):
        return False
    if hint is float:
        return isinstance(value, int | float)
    if hint is Path:
        return isinstance(value, str | Path)
    if origin is dict:
        return isinstance(value, dict) and all(
            _fits(k, args[0]) and _fits(v, args[1]) for k, v in value.items())
    if origin is tuple:
        if not isinstance(value, tuple):
            return False
        if len(args) == 2 and args[1] is Ellipsis:
            return all(_fits(v, args[0]) for v in value)
        return len(args) == len(value) and all(map(_fits, value, args))
    if isinstance(hint, type) and origin is None:
        try:
            return isinstance(value, hint)
        except TypeError:  # a protocol that cannot be checked at run time
            return True
    return True


def _kind(hint: Any, plural: bool = False) -> str:
    """An annotation in the words of a JSON ``--option`` value."""
    words = {int: ("an integer", "integers"), float: ("a number", "numbers"),
             bool: ("true or false", "true or false"), str: ("a string", "strings"),
             type(None): ("null", "nulls"), Path: ("a path", "paths")}
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_kind(a, plural) for a in args)
    if origin is dict:
        return f"{'objects' if plural else 'an object'} of {_kind(args[1], True)}"
    if origin is tuple:
        head = "lists" if plural else "a list"
        return f"{head} of {_kind(args[0], True)}" if args[-1] is Ellipsis else \
            f"{head} of {len(args)}"
    if hint in words:
        return words[hint][plural]
    return str(getattr(hint, "__name__", hint))


def _build_updater(name: str, options: dict[str, Any], given: dict[str, Any]) -> Any:
    """``make_updater``; a value the factory refuses beyond its annotation names the options."""
    try:
        return make_updater(name, **options)
    except UpdaterError:
        raise
    except (TypeError, ValueError) as exc:
        if not given:
            raise
        values = ", ".join(f"{k}={json.dumps(_jsonable(v))}" for k, v in given.items())
        raise UpdaterError(f"updater {name!r}: an --option value was refused ({values}): "
                           f"{exc}") from None


def _offline_database(options: dict[str, Any]) -> tuple[np.ndarray, np.ndarray] | None:
    """The offline (d, F) the updater was given (``--offline``, or a model file's own)."""
    if "offline" in options:
        d, f = options["offline"]
        return np.asarray(d), np.asarray(f)
    if "model_file" in options:
        from .modelfile import load_model

        model = load_model(Path(options["model_file"]))
        return model.offline_d, model.offline_force
    return None


def _relative(value: float, base: float) -> str:
    """``x % lower`` / ``x % higher`` than ``base`` (``equal`` when both are 0)."""
    if base == 0.0:
        return "equal" if value == 0.0 else "higher (the baseline is exact)"
    change = 100.0 * (value - base) / base
    return f"{abs(change):.1f} % {'lower' if change < 0 else 'higher'}"


def _jsonable(value: Any) -> Any:
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, tuple):
        return list(value)
    return value


def _write_predictions(path: Path, disp: np.ndarray, pred: np.ndarray,
                       true: np.ndarray | None, units: Units) -> None:
    to_d, to_f = 1.0 / units.to_mm, 1.0 / units.to_kn
    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["step", "disp", "force_pred", *(["force_true"] if true is not None else [])])
        for i in range(len(pred)):
            row = [i, repr(float(disp[i]) * to_d), repr(float(pred[i]) * to_f)]
            if true is not None:
                row.append(repr(float(true[i]) * to_f))
            w.writerow(row)
    tmp.replace(path)
