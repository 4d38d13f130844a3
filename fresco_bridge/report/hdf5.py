"""HDF5 export of a run (``fresco-bridge runs export --format hdf5``); h5py is imported lazily.

Layout (every dataset has a ``units`` attribute; ``1`` means dimensionless)::

    /                      attrs: run, run_json (run.json text), format_version
    /config                the config.toml snapshot (string), when present
    /sites/<site>/         attrs: actuators
        time step session  committed steps (s, 1, 1)
        cmd_disp meas_disp meas_force   (steps × actuators; mm, mm, kN)
        monitor/           online monitors per committed step, when recorded:
                           step session tracking_error (mm) ti (mm²) nrms fei_amplitude (1)
                           fei_delay (s); NaN where a monitor had no value yet
        update/            an updatable site's update lines (format 5): step session
                           through (the source step learned through) secs (s) err (kN;
                           NaN where the updater made no one-step prediction)
        correction/        a site's displacement corrections (format 6), as ``export
                           --corrections``: per corrected trial step session target
                           (trials × actuators, mm) outcome corrections (1) residual (mm);
                           per command (the target's own first) trial (its row in the
                           per-trial datasets) iteration (0: the target's own) command
                           measured (commands × actuators, mm)
    /events/               seq t (s since the bridge started) site session kind reason
                           extra (JSON text of the other fields)
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..record.export import CorrectionLine
from ..runs import Run, RunDirError

HDF5_FORMAT_VERSION = 1
_EVENT_KEYS = ("seq", "t", "kind", "site", "session", "event", "reason")


def _put(group: Any, name: str, data: Any, units: str) -> None:
    ds = group.create_dataset(name, data=data)
    ds.attrs["units"] = units


def _opt(v: float | None) -> float:
    return math.nan if v is None else v


def _corrections(group: Any, lines: list[CorrectionLine], str_dt: Any) -> None:
    n = max(len(c.target) for c in lines)

    def rows(vectors: list[tuple[float, ...]]) -> np.ndarray:
        return np.array([v + (math.nan,) * (n - len(v)) for v in vectors],
                        dtype=np.float64).reshape(len(vectors), n)

    _put(group, "step", np.array([c.step for c in lines], dtype=np.int64), "1")
    _put(group, "session", np.array([c.session for c in lines], dtype=np.int64), "1")
    _put(group, "target", rows([c.target for c in lines]), "mm")
    group.create_dataset("outcome", data=[c.outcome for c in lines], dtype=str_dt)
    _put(group, "corrections", np.array([c.corrections for c in lines], dtype=np.int64), "1")
    _put(group, "residual", np.array([c.residual for c in lines], dtype=np.float64), "mm")
    _put(group, "trial", np.array([i for i, c in enumerate(lines) for _ in c.commands],
                                  dtype=np.int64), "1")
    _put(group, "iteration", np.array([k for c in lines for k in range(len(c.commands))],
                                      dtype=np.int64), "1")
    _put(group, "command", rows([v for c in lines for v in c.commands]), "mm")
    _put(group, "measured", rows([v for c in lines for v in c.measured]), "mm")


def export_hdf5(run: Run, out_path: Path, *, site: str | None = None) -> int:
    """Write ``run`` (or one site of it) to ``out_path``; returns the committed steps written."""
    import h5py  # type: ignore[import-untyped]

    sites = [s for s in run.sites if site is None or s == site]
    if site is not None and not sites:
        raise RunDirError(f"{run.directory}: no site {site!r} in this run (sites: "
                          f"{', '.join(run.sites) or 'none'})")
    str_dt = h5py.string_dtype()
    written = 0
    with h5py.File(out_path, "w") as f:
        f.attrs["run"] = run.name
        f.attrs["run_json"] = json.dumps(run.meta)
        f.attrs["format_version"] = HDF5_FORMAT_VERSION
        if run.config_text is not None:
            f.create_dataset("config", data=run.config_text, dtype=str_dt)
        for name in sites:
            steps = [s for s in run.steps if s.site == name]
            n = max((len(s.cmd_disp) for s in steps), default=1)
            g = f.create_group(f"sites/{name}")
            g.attrs["actuators"] = n

            def mat(attr: str, rows: list[Any] = steps, n: int = n) -> np.ndarray:
                return np.array([tuple(getattr(r, attr)) + (math.nan,) * (n - len(getattr(r, attr)))
                                 for r in rows], dtype=np.float64).reshape(len(rows), n)

            _put(g, "time", np.array([s.time for s in steps], dtype=np.float64), "s")
            _put(g, "step", np.array([s.step for s in steps], dtype=np.int64), "1")
            _put(g, "session", np.array([s.session for s in steps], dtype=np.int64), "1")
            _put(g, "cmd_disp", mat("cmd_disp"), "mm")
            _put(g, "meas_disp", mat("meas_disp"), "mm")
            _put(g, "meas_force", mat("meas_force"), "kN")
            written += len(steps)
            mons = [m for m in run.monitors if m.site == name]
            if mons:
                mg = g.create_group("monitor")
                _put(mg, "step", np.array([m.step for m in mons], dtype=np.int64), "1")
                _put(mg, "session", np.array([m.session for m in mons], dtype=np.int64), "1")
                for key, units in (("tracking_error", "mm"), ("ti", "mm²"), ("nrms", "1"),
                                   ("fei_amplitude", "1"), ("fei_delay", "s")):
                    _put(mg, key, np.array([_opt(getattr(m, key)) for m in mons],
                                           dtype=np.float64), units)
            ups = [u for u in run.updates if u.get("site") == name]
            if ups:
                ug = g.create_group("update")
                for key, units, dtype in (("step", "1", np.int64), ("session", "1", np.int64),
                                          ("through", "1", np.int64)):
                    _put(ug, key, np.array([int(u[key]) for u in ups], dtype=dtype), units)
                _put(ug, "secs", np.array([float(u["secs"]) for u in ups], dtype=np.float64), "s")
                _put(ug, "err", np.array([float(u.get("err", math.nan)) for u in ups],
                                         dtype=np.float64), "kN")
            corrections = [c for c in run.corrections if c.site == name]
            if corrections:
                _corrections(g.create_group("correction"), corrections, str_dt)
        events = [e for e in run.events if site is None or e.get("site") == site]
        eg = f.create_group("events")
        _put(eg, "seq", np.array([int(e.get("seq", 0)) for e in events], dtype=np.int64), "1")
        _put(eg, "t", np.array([float(e.get("t", math.nan)) for e in events], dtype=np.float64),
             "s")
        _put(eg, "session", np.array([int(e.get("session", 0)) for e in events],
                                     dtype=np.int64), "1")
        for key, src in (("site", "site"), ("kind", "event"), ("reason", "reason")):
            eg.create_dataset(key, data=[str(e.get(src, "")) for e in events], dtype=str_dt)
        eg.create_dataset("extra", dtype=str_dt, data=[
            json.dumps({k: v for k, v in e.items() if k not in _EVENT_KEYS}) for e in events])
    return written
