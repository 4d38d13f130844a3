"""A diagnosis's plots (PNG bytes), in the shared styles of ``fresco_bridge.report.figures``:
the measurement in grey underneath, the sim without the effect in blue, with it in red.

The overlay puts each model in its own panel over the measurement (shared axes) with the force
residuals in time below: in one panel the measurement and a well-fitting sim + effect were
indistinguishable (issue 27). Residual axes span at least the noise floor, so round-off is not
drawn as a misfit.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..numbers import pct
from .result import Diagnosis, Series

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["overlay_figure", "plots"]


def _series(result: Diagnosis) -> Series:
    if result.series is None:
        raise ValueError("a diagnosis read from JSON has no series to plot")
    return result.series


def overlay_figure(result: Diagnosis) -> Figure:
    """The measurement against the sim without (left) and with (right) the winning effect, each
    model in its own panel over the measurement in grey (the study's convention: grey shows only
    where the model misses), on shared axes; below, both force residuals in time with the
    withheld (scored) part shaded and each model's withheld gap in the legend."""
    from matplotlib.figure import Figure

    from ..report.diagnosis import BASIS_WORDS
    from ..report.figures import (
        BASELINE,
        GRID_ALPHA,
        LABEL_SIZE,
        PREDICTION,
        SUPTITLE_SIZE,
        TRUTH,
        plot_stride,
        style_panel,
    )

    s = _series(result)
    t, c, m, f = s.time, s.cmd, s.meas_disp, s.force
    sim, best, stop = s.sim, s.best, s.stop
    verdict = result.verdict
    name = verdict.effect
    added = best is not None and verdict.adds_an_effect
    best_f = best if best is not None else sim
    gap_base, gap_best = verdict.gap_before_pct, verdict.gap_after_pct  # as it quotes
    k = plot_stride(t.size)
    fig = Figure(figsize=(10.0, 7.6))
    axes = fig.subplot_mosaic([["base", "effect"], ["residual", "residual"]],
                              height_ratios=[3.0, 2.0])
    axes["effect"].sharex(axes["base"])
    axes["effect"].sharey(axes["base"])
    x = m if m is not None else c
    sim_d = s.sim_disp if s.sim_disp is not None else c
    best_d = s.best_disp if s.best_disp is not None else c
    for key, model, disp, style, label, gap in (
            ("base", sim, sim_d, BASELINE, f"sim ({result.baseline['kind']} baseline)",
             gap_base),
            ("effect", best if added else None, best_d, PREDICTION, f"sim + {name}", gap_best)):
        ax = axes[key]
        ax.plot(x[::k], f[::k], label="measured", **{**TRUTH, "lw": 1.6, "color": "0.7"})
        if model is not None:
            ax.plot(disp[::k], model[::k], label=label, **{**style, "lw": 0.8, "ls": "-"})
            title = f"{label}: withheld gap {pct(gap)}"
        else:
            ax.text(0.97, 0.04, f"verdict {name}:\nno effect added to the sim", ha="right",
                    va="bottom", transform=ax.transAxes, fontsize=LABEL_SIZE, color="0.3",
                    bbox={"boxstyle": "round,pad=0.3", "fc": "white", "ec": "0.8"})
            title = f"verdict {name}: the sim alone is the model"
        style_panel(ax, title, "displacement (mm)", "force (kN)")
        ax.legend(fontsize=LABEL_SIZE, loc="upper left")
    ax = axes["residual"]
    ax.axvspan(float(t[stop]), float(t[-1]), color="0.93", zorder=0,
               label="withheld part (scored)")
    ax.plot(t[::k], (f - sim)[::k], label=f"measured − sim (gap {pct(gap_base)})",
            **{**BASELINE, "ls": "-", "lw": 0.7})
    if added:
        ax.plot(t[::k], (f - best_f)[::k], label=f"measured − (sim + {name}) (gap {pct(gap_best)})",
                **{**PREDICTION, "lw": 0.8})
    ax.axhline(0.0, color="0.3", lw=0.6)
    _residual_span(ax, result, f - sim, f - best_f if added else f - sim)
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi + 0.3 * (hi - lo))  # headroom: the legend never hides a residual peak
    style_panel(ax, "force residual in time", "time (s)", "force residual (kN)")
    ax.grid(alpha=GRID_ALPHA)
    ax.legend(fontsize=LABEL_SIZE, loc="upper left", ncol=3)
    basis = verdict.gap_basis
    fig.suptitle("hysteresis: the measurement (grey) against the sim without and with the "
                 f"effect (withheld gaps {BASIS_WORDS.get(basis, basis)}, as the verdict)",
                 fontsize=SUPTITLE_SIZE)
    fig.tight_layout()
    return fig


def _residual_span(ax: Axes, result: Diagnosis, *residuals: np.ndarray) -> None:
    """A residual axis spans at least ± the noise floor of the peak force: round-off residuals
    (a record the sim matches exactly) must not fill the axis and look like a misfit."""
    from ..report.figures import min_span

    f = _series(result).force
    peak = float(np.nanmax(np.abs(f))) if np.isfinite(f).any() else 0.0
    floor = result.noise_floor["floor_pct"] / 100.0
    min_span(ax, np.concatenate(residuals), 2.0 * floor * peak)


def plots(result: Diagnosis) -> dict[str, bytes]:
    """Every plot of ``diagnose --report``: ``{file name: PNG bytes}``."""
    from matplotlib.figure import Figure

    from ..report.figures import BASELINE, GRID_ALPHA, PREDICTION, plot_stride, png_bytes
    from ..report.figures import synchronization as sync_figure
    from ..runs import SessionSignals
    from .localise import phase_angle

    s = _series(result)
    t, c, m, f = s.time, s.cmd, s.meas_disp, s.force
    sim, best, stop = s.sim, s.best, s.stop
    name = result.verdict.effect
    added = best is not None and result.verdict.adds_an_effect
    best_f = best if best is not None else sim
    k = plot_stride(t.size)
    files: dict[str, bytes] = {}

    files["hysteresis_overlay.png"] = png_bytes(overlay_figure(result))

    fig = Figure(figsize=(7.2, 4.8))
    ax = fig.add_subplot()
    phase = phase_angle(c)
    ax.scatter(phase[::k], (f - sim)[::k], s=3, alpha=0.5, color=BASELINE["color"],
               label="measured − sim (baseline)")
    if added:
        ax.scatter(phase[::k], (f - best_f)[::k], s=3, alpha=0.5, color=PREDICTION["color"],
                   label=f"measured − (sim + {name})")
    ax.set_xlabel("loop phase of the command (deg; 0 = positive peak, ±180 = negative peak)")
    ax.set_ylabel("force residual (kN)")
    _residual_span(ax, result, f - sim, f - best_f if added else f - sim)
    ax.set_title("force residual against loop phase")
    ax.grid(alpha=GRID_ALPHA)
    ax.legend(fontsize="small", markerscale=4)
    fig.tight_layout()
    files["residual_vs_phase.png"] = png_bytes(fig)

    meas = (m if m is not None else np.full_like(c, math.nan))[:, None]
    signals = SessionSignals("record", 1, t, np.arange(t.size), c[:, None], meas, f[:, None])
    files["measured_vs_command.png"] = sync_figure("record", [signals])

    fig = Figure(figsize=(7.2, 4.8))
    ax = fig.add_subplot()
    dt = float(np.median(np.diff(t)))
    freqs = np.fft.rfftfreq(t.size, dt)[1:]
    for label, r, color in (("force: measured − sim", f - sim, BASELINE["color"]),
                            (f"force: measured − (sim + {name})",
                             f - best_f if added else None, PREDICTION["color"])):
        if r is None:
            continue
        spectrum = np.abs(np.fft.rfft((r - r.mean()) * np.hanning(r.size)))[1:]
        ax.semilogy(freqs, spectrum, lw=0.8, color=color, label=label)
    ax.axvline(1.0 / (2.0 * dt), color="0.5", lw=0.6)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("|FFT| of the residual (kN, Hann window)")
    ax.set_title(f"residual spectrum (withheld part starts at t = {t[stop]:.4g} s)")
    ax.grid(alpha=GRID_ALPHA, which="both")
    ax.legend(fontsize="small")
    fig.tight_layout()
    files["residual_spectrum.png"] = png_bytes(fig)

    return files
