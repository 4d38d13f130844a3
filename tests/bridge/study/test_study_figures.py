"""The study's figures read for every case: bars on a scale where a 0.3 kN case and a 37 kN case
are both visible, force errors as one panel per case on shared axes; drawn from histories shaped
as the study's (issue 27, "Pictures")."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from fresco_bridge.study.report import (
    bars_figure,
    force_error_figure,
    hysteresis_figure,
    write_figures,
)
from fresco_bridge.study.simulate import CaseHistory

MAETH = {"reference": 0.0, "conventional_paper": 37.0, "conventional_calibrated": 5.0,
         "offline_ann": 12.0, "online_ukf": 2.4, "online_ann": 1.3, "online_improved": 0.3}
"""The issue's spread: ``conventional_paper`` 37 kN beside ``online_improved`` 0.3 kN and
``online_ann`` 1.3 kN, which a linear axis could not tell apart."""
MIN_BAR_PX = 8.0
"""A bar narrower than this (at the report's 100 dpi) cannot be read or compared."""


def _document() -> dict[str, Any]:
    def case(maeth: float) -> dict[str, Any]:
        return {"maeth": maeth, "rmseth": maeth / 4, "maesd": [maeth / 10, maeth / 8]}

    return {"layouts": {layout: {"cases": {n: case(v * scale) for n, v in MAETH.items()}}
                        for layout, scale in (("paper", 1.0), ("generalisation", 0.9))}}


def _histories(steps: int = 300) -> dict[str, dict[str, CaseHistory]]:
    t = np.arange(steps) * 0.01
    drift = 10.0 * np.sin(2 * np.pi * 0.5 * t)
    true = 15.0 * np.tanh(drift / 3.0)

    def history(error: float) -> CaseHistory:
        twin = true + error * np.sin(2 * np.pi * 1.3 * t)
        floors = np.column_stack([drift, 2 * drift])
        return CaseHistory(drift, true, drift, twin, true, twin, np.zeros(steps), floors)

    return {layout: {n: history(v) for n, v in MAETH.items()}
            for layout in ("paper", "generalisation")}


def _bar_widths_px(fig: Figure, ax: Axes) -> list[float]:
    """Each bar's visible length in pixels (clipped to the axes)."""
    fig.canvas.draw()
    box = ax.get_window_extent()
    return [min(b.x1, box.x1) - max(b.x0, box.x0)
            for b in (p.get_window_extent() for p in ax.patches
                      if isinstance(p, Rectangle) and np.isfinite(p.get_width()))]


def test_bars_show_the_smallest_and_the_largest_case_legibly() -> None:
    fig = bars_figure(_document())
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert len(axes) == 3  # MAETH, MAESD story 1, MAESD story 2
    for ax in axes:
        assert ax.get_xscale() == "log", ax.get_title()
        widths = _bar_widths_px(fig, ax)
        assert len(widths) == 2 * (len(MAETH) - 1)  # every learning case, both layouts
        assert min(widths) >= MIN_BAR_PX, (ax.get_title(), min(widths))
        assert max(widths) > 2 * min(widths)  # and the spread still shows
    maeth = axes[0]
    labels = {t.get_text().strip() for t in maeth.texts}
    assert {"37", "0.3", "1.3", "0.27"} <= labels  # every bar says its value
    names = [t.get_text() for t in maeth.get_yticklabels()]
    assert names[0] == "conventional_paper" and "reference" not in names


def test_a_linear_axis_would_have_hidden_the_small_cases() -> None:
    """The check above can fail: the same bars on the old linear axis are under MIN_BAR_PX."""
    fig = bars_figure(_document())
    ax = fig.axes[0]
    ax.set_xscale("linear")
    ax.set_xlim(0.0, 40.0)
    assert min(_bar_widths_px(fig, ax)) < MIN_BAR_PX


def test_force_errors_are_small_multiples_one_axes_per_case_on_shared_axes() -> None:
    histories = _histories()
    fig = force_error_figure("generalisation", histories["generalisation"], "twin_true_force",
                             _document())
    axes = [ax for ax in fig.axes if ax.get_visible()]
    learning = [n for n in MAETH if n != "reference"]
    assert [ax.get_title() for ax in axes] == learning
    first = axes[0]
    for ax in axes:
        assert ax.get_yscale() == "log"
        assert first.get_shared_y_axes().joined(first, ax)
        assert first.get_shared_x_axes().joined(first, ax)
        red = [ln for ln in ax.get_lines() if ln.get_color() == "C3"]
        assert len(red) == 1  # the panel's own case, once
    corner = " ".join(t.get_text() for t in axes[-1].texts)
    assert "MAETH 0.27 kN" in corner


def test_hysteresis_grid_keeps_one_panel_per_case_with_true_under_twin() -> None:
    fig = hysteresis_figure("paper", _histories()["paper"], "tested_force")
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert len(axes) == len(MAETH)
    true, twin = axes[0].get_lines()
    assert true.get_zorder() < twin.get_zorder() and true.get_color() != twin.get_color()


def test_write_figures_writes_every_png(tmp_path: Path) -> None:
    files = write_figures(_document(), _histories(), tmp_path)
    assert sorted(p.name for p in files) == sorted(
        ["hysteresis_paper.png", "force_error_paper.png", "hysteresis_generalisation.png",
         "force_error_generalisation.png", "bars.png"])
    for path in files:
        assert path.read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize("value", [0.0, float("nan")])
def test_a_case_without_a_positive_value_gets_a_label_and_no_bar(value: float) -> None:
    document = _document()
    document["layouts"]["paper"]["cases"]["online_improved"]["maeth"] = value
    fig = bars_figure(document)
    fig.canvas.draw()
    labels = [t.get_text().strip() for t in fig.axes[0].texts]
    assert ("0" if value == 0.0 else "—") in labels


@pytest.mark.parametrize("kept", [("reference",), ("reference", "online_improved")])
def test_a_study_of_few_cases_still_draws_every_figure(tmp_path: Path,
                                                       kept: tuple[str, ...]) -> None:
    document = _document()
    for body in document["layouts"].values():
        body["cases"] = {n: m for n, m in body["cases"].items() if n in kept}
    histories = {layout: {n: h for n, h in cases.items() if n in kept}
                 for layout, cases in _histories().items()}
    assert len(write_figures(document, histories, tmp_path)) == 5
    fig = force_error_figure("paper", histories["paper"], "tested_force", document)
    (ax,) = [ax for ax in fig.axes if ax.get_visible()]
    assert ax.get_title() == ("" if kept == ("reference",) else "online_improved")
    assert len(fig.legends) == (0 if kept == ("reference",) else 1)
    if kept != ("reference",):
        assert [t.get_text() for t in fig.legends[0].get_texts()] == ["the panel's case"]
