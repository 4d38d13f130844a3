"""The diagnosis overlay tells the measurement from each sim at a glance: each model in its own
panel over the measurement (grey, underneath, wider), shared axes, and a residual panel with the
withheld part marked (issue 27, "Pictures"). Drawn from a real diagnosis of a backlash record."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest
from matplotlib.colors import to_rgba
from matplotlib.lines import Line2D

from benchmarks.diagnosis.synth import synthetic_record
from fresco_bridge.diagnosis.figures import overlay_figure
from fresco_bridge.diagnosis.result import Diagnosis
from fresco_bridge.diagnosis.verdict import Options, diagnose


@pytest.fixture(scope="module")
def result() -> Diagnosis:
    record = synthetic_record("backlash", 2, steps=600).record
    out = diagnose(record, Options(effects=("backlash", "friction"), pairs=False))
    assert out.verdict.effect == "backlash"
    return out


def _data_lines(ax: Any) -> list[Line2D]:
    return [ln for ln in ax.get_lines() if len(ln.get_xdata()) > 2]


def test_each_model_has_its_panel_over_the_measurement(result: Diagnosis) -> None:
    fig = overlay_figure(result)
    base, effect, _residual = fig.axes
    assert base.get_shared_x_axes().joined(base, effect)
    assert base.get_shared_y_axes().joined(base, effect)
    colours = []
    kind = result.baseline["kind"]
    for ax, model_label in ((base, f"sim ({kind} baseline)"), (effect, "sim + backlash")):
        measured, model = _data_lines(ax)
        assert (measured.get_label(), model.get_label()) == ("measured", model_label)
        assert measured.get_zorder() < model.get_zorder()  # the model on top
        assert measured.get_linewidth() > model.get_linewidth()  # grey shows where it misses
        assert to_rgba(measured.get_color()) != to_rgba(model.get_color())
        colours.append(to_rgba(model.get_color()))
        assert "withheld gap" in ax.get_title()
    assert colours[0] != colours[1]  # baseline and baseline + effect never share a colour


def test_the_residual_panel_marks_the_withheld_part(result: Diagnosis) -> None:
    fig = overlay_figure(result)
    residual = fig.axes[2]
    lines = _data_lines(residual)
    assert [str(ln.get_label()).split(" (gap")[0] for ln in lines] == [
        "measured − sim", "measured − (sim + backlash)"]
    (span,) = residual.patches
    assert result.series is not None
    t = result.series.time
    assert span.get_x() == pytest.approx(float(t[result.series.stop]))  # type: ignore[attr-defined]


def test_a_verdict_without_an_effect_says_so_in_its_panel(result: Diagnosis) -> None:
    none = replace(result, verdict=replace(result.verdict, effect="none"))
    fig = overlay_figure(none)
    effect = fig.axes[1]
    assert [ln.get_label() for ln in _data_lines(effect)] == ["measured"]
    assert any("no effect added" in t.get_text() for t in effect.texts)
    assert len(_data_lines(fig.axes[2])) == 1
