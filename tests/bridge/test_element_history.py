"""One CSV vocabulary for every history the tools read (``element_history.COLUMNS``/``ALIASES``).

The bridge's export names every column; a ``time,disp,force`` file (the shipped
``examples/data``) is the measured displacement and force; a header with both a name and its
alias is read by the name; every column error lists the same accepted set, in the same words as
``diagnose --help``; ``diagnose`` and ``updater replay``'s reader read one file alike.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fresco_bridge.diagnosis.load import DiagnosisInputError, load_record
from fresco_bridge.element_history import (
    ALIASES,
    COLUMNS,
    HistoryInputError,
    read_element_history,
    vocabulary,
)
from fresco_bridge.updating.histories import read_history


def _csv(tmp_path: Path, header: str, n: int = 150) -> Path:
    t = np.arange(n) * 0.01
    d = 5.0 * np.sin(2.0 * np.pi * t)
    rows = [f"{a:.4f},{b:.6f},{2.0 * b + 0.1:.6f}" for a, b in zip(t, d, strict=True)]
    path = tmp_path / "h.csv"
    path.write_text(header + "\n" + "\n".join(rows) + "\n", encoding="utf-8")
    return path


def test_the_short_names_are_the_measured_channels(tmp_path: Path) -> None:
    path = _csv(tmp_path, "time,disp,force")
    h = read_element_history(path, ("time", "meas_disp", "meas_force"))
    assert set(h.columns) == {"time", "meas_disp", "meas_force"}
    rec = load_record(path)
    assert rec.no_command and rec.meas_disp is None  # the one displacement is the measured one
    hist = read_history(path)
    assert np.array_equal(hist.disp, rec.cmd) and hist.force is not None
    assert np.array_equal(hist.force, rec.force)


def test_a_name_wins_over_its_alias(tmp_path: Path) -> None:
    t = np.arange(3) * 0.1
    path = tmp_path / "both.csv"
    path.write_text("time,force,meas_force\n" + "".join(
        f"{x},{1.0 + i},{10.0 + i}\n" for i, x in enumerate(t)), encoding="utf-8")
    h = read_element_history(path, ("time", "meas_force"))
    assert list(h.columns["meas_force"]) == [10.0, 11.0, 12.0]


def test_every_column_error_names_the_same_set(tmp_path: Path) -> None:
    assert vocabulary() == ("time, cmd_disp (or cmd), meas_disp (or disp), "
                            "meas_force (or force)")
    assert set(ALIASES) <= set(COLUMNS)
    path = _csv(tmp_path, "time,position,load")
    with pytest.raises(HistoryInputError, match=r"missing column\(s\) meas_force \(or force\)"):
        read_element_history(path, ("time", "meas_force"))
    with pytest.raises(DiagnosisInputError) as diag:
        load_record(path)
    assert "meas_force (or force)" in str(diag.value)
    no_disp = tmp_path / "f.csv"
    no_disp.write_text("time,force\n" + "".join(f"{i * 0.01},{i}\n" for i in range(150)))
    with pytest.raises(DiagnosisInputError) as missing:
        load_record(no_disp)
    assert vocabulary() in str(missing.value)
    empty = tmp_path / "e.csv"
    empty.write_text("")
    with pytest.raises(HistoryInputError, match=r"meas_force \(or force\)"):
        read_element_history(empty, ("time", "meas_force"))
    with pytest.raises(ValueError, match="not history columns: force"):
        read_element_history(path, ("time", "force"))
