"""The report's figures, rendered to PNG bytes with matplotlib's Agg backend, and the one home
of the figures' look (``TRUTH``, ``PREDICTION``, ``BASELINE``, sizes, :func:`panel_grid` for
small multiples) that the study's and the diagnosis's figures share.

Only the after-the-run deliverables (the report, ``study paper``'s and ``diagnose``'s plots)
import this module, so matplotlib never loads in the daemon. Figures are built on
``matplotlib.figure.Figure`` (no pyplot global state). Long records are thinned to about
``MAX_POINTS`` points per line for drawing; the numbers in the report use every step.
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from ..record.export import MonitorLine
from ..runs import SessionSignals

MAX_POINTS = 20_000
DPI = 100

# One home for the look of the comparison figures (the study's and the diagnosis's), after the
# study's hysteresis grid: the truth or the measurement in grey underneath, the model that is
# being judged in red on top (grey shows only where it misses), a baseline model dashed blue.
TRUTH: dict[str, Any] = {"color": "0.4", "lw": 0.7, "zorder": 2}
PREDICTION: dict[str, Any] = {"color": "C3", "lw": 0.7, "zorder": 3}
BASELINE: dict[str, Any] = {"color": "C0", "lw": 0.8, "ls": "--", "zorder": 2.5}
GRID_ALPHA = 0.3
TITLE_SIZE = 9
LABEL_SIZE = 8
SUPTITLE_SIZE = 10
PANEL_SIZE = (3.6, 3.2)
"""Inches per panel of a grid of small multiples."""


def png_bytes(fig: Figure) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    return buf.getvalue()


def plot_stride(n: int) -> int:
    return max(1, math.ceil(n / MAX_POINTS))


def _label(sig: SessionSignals, a: int, many_sessions: bool) -> str:
    parts = []
    if sig.cmd.shape[1] > 1:
        parts.append(f"actuator {a + 1}")
    if many_sessions:
        parts.append(f"session {sig.session}")
    return ", ".join(parts)


def _legend(ax: Axes) -> None:
    _handles, labels = ax.get_legend_handles_labels()
    if any(labels):
        ax.legend(fontsize="small")


def _no_data(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4")


def min_span(ax: Axes, values: np.ndarray, span: float) -> None:
    """Keep at least ``span`` visible around the data, so round-off does not fill the axis."""
    finite = values[np.isfinite(values)]
    if finite.size and float(finite.max() - finite.min()) < span:
        mid = 0.5 * float(finite.max() + finite.min())
        ax.set_ylim(mid - span / 2, mid + span / 2)


def panel_grid(n: int, *, cols: int = 4, sharex: bool = False, sharey: bool = False,
               size: tuple[float, float] = PANEL_SIZE) -> tuple[Figure, list[Axes]]:
    """``n`` panels (small multiples) in rows of at most ``cols``; spare cells hidden. Shared
    axes are what make panels comparable at a glance, so callers comparing one quantity pass
    ``sharex``/``sharey``; tick labels then show on the outer panels only."""
    if n < 1:
        raise ValueError(f"panel_grid: need at least one panel (got {n})")
    cols = min(cols, n)
    rows = -(-n // cols)
    fig = Figure(figsize=(size[0] * cols, size[1] * rows))
    grid = fig.subplots(rows, cols, squeeze=False, sharex=sharex, sharey=sharey)
    cells = list(grid.flat)
    for ax in cells[n:]:
        ax.set_visible(False)
    if sharex:  # the last visible panel of each column carries the x ticks
        for ax in cells[max(0, n - cols):n]:
            ax.xaxis.set_tick_params(labelbottom=True)
    return fig, cells[:n]


def style_panel(ax: Axes, title: str, xlabel: str, ylabel: str) -> None:
    """A small multiple's title, axis labels and grid, in the shared sizes."""
    ax.set_title(title, fontsize=TITLE_SIZE)
    ax.set_xlabel(xlabel, fontsize=LABEL_SIZE)
    ax.set_ylabel(ylabel, fontsize=LABEL_SIZE)
    ax.grid(alpha=GRID_ALPHA)


def outer_labels(axes: Sequence[Axes], cols: int) -> None:
    """Axis labels on the outer panels of a shared grid only (bottom row of each column, first
    column), as :func:`panel_grid` laid them out."""
    cols = min(cols, len(axes))
    for i, ax in enumerate(axes):
        if i + cols < len(axes):
            ax.set_xlabel("")
        if i % cols:
            ax.set_ylabel("")


def hysteresis(site: str, signals: Sequence[SessionSignals], *, served: bool = False) -> bytes:
    """Measured force against measured displacement, per actuator and session; ``served``: an
    updatable site's, which measures nothing (its trial displacement and predicted force)."""
    fig = Figure(figsize=(6.4, 4.8))
    ax = fig.add_subplot()
    many = len(signals) > 1
    for sig in signals:
        k = plot_stride(sig.step.size)
        for a in range(sig.cmd.shape[1]):
            ax.plot(sig.meas[::k, a], sig.force[::k, a], lw=0.8,
                    label=_label(sig, a, many) or None)
    if not signals:
        _no_data(ax, "no committed steps")
    ax.set_xlabel("trial displacement (mm)" if served else "measured displacement (mm)")
    ax.set_ylabel("served force, predicted (kN)" if served else "measured force (kN)")
    ax.set_title(f"{site}: served hysteresis" if served else f"{site}: hysteresis")
    ax.grid(alpha=GRID_ALPHA)
    _legend(ax)
    fig.tight_layout()
    return png_bytes(fig)


MARKER_COLORS = {"hold": "tab:red", "limit": "tab:orange", "monitor-warning": "tab:purple"}


def command_vs_measured(
    site: str, signals: Sequence[SessionSignals],
    markers: Sequence[tuple[float, str]] = (),
) -> bytes:
    """Command and measured displacement over the integrator's time; ``markers`` are
    (time, event kind) drawn as vertical lines (holds, limit hits, monitor warnings)."""
    fig = Figure(figsize=(9.6, 4.0))
    ax = fig.add_subplot()
    many = len(signals) > 1
    for sig in signals:
        k = plot_stride(sig.step.size)
        for a in range(sig.cmd.shape[1]):
            label = _label(sig, a, many)
            sep = ", " if label else ""
            ax.plot(sig.time[::k], sig.cmd[::k, a], lw=0.9, label=f"command{sep}{label}")
            ax.plot(sig.time[::k], sig.meas[::k, a], lw=0.9, ls="--",
                    label=f"measured{sep}{label}")
    if not signals:
        _no_data(ax, "no committed steps")
    labelled: set[str] = set()
    for t, kind in markers:
        ax.axvline(t, color=MARKER_COLORS.get(kind, "0.3"), lw=0.8, ls=":",
                   label=None if kind in labelled else kind)
        labelled.add(kind)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("displacement (mm)")
    ax.set_title(f"{site}: command vs measured displacement")
    ax.grid(alpha=GRID_ALPHA)
    _legend(ax)
    fig.tight_layout()
    return png_bytes(fig)


def error_monitors(
    site: str,
    signals: Sequence[SessionSignals],
    ti: Sequence[np.ndarray],
    monitors: Sequence[MonitorLine],
    warn_tracking_error: float | None,
) -> bytes:
    """Tracking error and TI (offline, every committed step) and the recorded online monitors.

    ``ti`` holds the offline TI of actuator 1 per session (same order as ``signals``).
    """
    fig = Figure(figsize=(9.6, 8.0))
    ax_e, ax_ti, ax_fei = fig.subplots(3, 1, sharex=True)
    many = len(signals) > 1
    times: dict[tuple[int, int], float] = {}
    for sig, ti_s in zip(signals, ti, strict=True):
        k = plot_stride(sig.step.size)
        for a in range(sig.cmd.shape[1]):
            err = sig.meas[:, a] - sig.cmd[:, a]
            ax_e.plot(sig.time[::k], err[::k], lw=0.8, label=_label(sig, a, many) or None)
        ax_ti.plot(sig.time[::k], ti_s[::k], lw=0.9,
                   label="offline (committed steps)" + (f", session {sig.session}" if many else ""))
        times.update({(sig.session, int(s)): float(t)
                      for s, t in zip(sig.step, sig.time, strict=True)})
    if warn_tracking_error is not None:
        for sign in (1.0, -1.0):
            ax_e.axhline(sign * warn_tracking_error, color="tab:red", lw=0.8, ls=":",
                         label="warning threshold" if sign > 0 else None)
    ax_e.set_ylabel("measured − command (mm)")
    ax_e.set_title(f"{site}: tracking error and error monitors")
    mons = [m for m in monitors if (m.session, m.step) in times]
    if mons:
        t = np.array([times[(m.session, m.step)] for m in mons])
        k = plot_stride(t.size)
        ax_ti.plot(t[::k], np.array([m.ti for m in mons])[::k], lw=0.9, ls="--",
                   label="online monitor (recorded)")
        amp = np.array([math.nan if m.fei_amplitude is None else m.fei_amplitude for m in mons])
        delay = np.array([math.nan if m.fei_delay is None else m.fei_delay for m in mons])
        ax_fei.plot(t[::k], amp[::k], color="tab:blue", lw=0.9, label="FEI amplitude")
        ax_fei.set_ylabel("FEI amplitude (1)", color="tab:blue")
        ax_delay = ax_fei.twinx()
        ax_delay.plot(t[::k], 1000.0 * delay[::k], color="tab:orange", lw=0.9,
                      label="FEI delay")
        ax_delay.set_ylabel("FEI delay (ms)", color="tab:orange")
        min_span(ax_fei, amp, 0.02)
        min_span(ax_delay, 1000.0 * delay, 0.2)  # round-off is not a delay worth a scale
        if not np.isfinite(amp).any():
            _no_data(ax_fei, "FEI window not yet full (fewer steps than telemetry.monitor_window)")
    else:
        _no_data(ax_fei, "no online monitor samples in the record (telemetry.monitors = false?)")
        ax_fei.set_ylabel("FEI")
    ax_ti.set_ylabel("tracking indicator (mm²)")
    ax_fei.set_xlabel("time (s)")
    for ax in (ax_e, ax_ti, ax_fei):
        ax.grid(alpha=GRID_ALPHA)
    _legend(ax_e)
    _legend(ax_ti)
    fig.tight_layout()
    return png_bytes(fig)


def synchronization(site: str, signals: Sequence[SessionSignals]) -> bytes:
    """Measured against command displacement (the synchronization subspace plot)."""
    fig = Figure(figsize=(5.6, 5.6))
    ax = fig.add_subplot()
    many = len(signals) > 1
    lo, hi = math.inf, -math.inf
    for sig in signals:
        k = plot_stride(sig.step.size)
        for a in range(sig.cmd.shape[1]):
            ax.plot(sig.cmd[::k, a], sig.meas[::k, a], lw=0.8, label=_label(sig, a, many) or None)
            both = np.concatenate([sig.cmd[:, a], sig.meas[:, a]])
            both = both[np.isfinite(both)]
            if both.size:
                lo, hi = min(lo, float(both.min())), max(hi, float(both.max()))
    if math.isfinite(lo):
        ax.plot([lo, hi], [lo, hi], color="0.5", lw=0.8, ls="--", label="perfect tracking")
    else:
        _no_data(ax, "no committed steps")
    ax.set_xlabel("command displacement (mm)")
    ax.set_ylabel("measured displacement (mm)")
    ax.set_title(f"{site}: synchronization subspace")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=GRID_ALPHA)
    _legend(ax)
    fig.tight_layout()
    return png_bytes(fig)


def updating(twin: str, source: str, twin_d: np.ndarray, twin_f: np.ndarray,
             twin_time: np.ndarray, source_time: np.ndarray, source_f: np.ndarray,
             steps: np.ndarray, behind: np.ndarray, update_ms: np.ndarray,
             error: np.ndarray) -> bytes:
    """An updatable site in six panels: the twin's hysteresis (its trial displacement against
    its predicted force), its predicted force beside the source's measured force in time, and
    per twin step the source's one-step error, how many source steps its answer lagged and the
    update time (in time and as a distribution)."""
    fig = Figure(figsize=(10.0, 10.0))
    axes = fig.subplots(3, 2)
    k = plot_stride(twin_d.size)
    ax = axes[0, 0]
    ax.plot(twin_d[::k], twin_f[::k], **{**PREDICTION, "lw": 0.8})
    ax.set_xlabel("twin displacement (mm)")
    ax.set_ylabel("predicted force (kN)")
    ax.set_title("twin hysteresis (predicted)", fontsize=10)
    ax = axes[0, 1]
    ks = plot_stride(source_f.size)
    ax.plot(source_time[::ks], source_f[::ks], **{**TRUTH, "lw": 0.8},
            label=f"measured at {source}")
    ax.plot(twin_time[::k], twin_f[::k], **{**PREDICTION, "lw": 0.8},
            label=f"served by {twin} (predicted)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("force (kN)")
    ax.set_title("predicted vs source force", fontsize=10)
    _legend(ax)
    ku = plot_stride(steps.size)
    ax = axes[1, 0]
    if np.isfinite(error).any():
        ax.plot(steps[::ku], error[::ku], lw=0.8, color="C1")
    elif steps.size:
        _no_data(ax, "the updater makes no one-step prediction")
    ax.set_xlabel("twin step")
    ax.set_ylabel("|F − F̂| (kN)")
    ax.set_title("source's one-step error (before learning it)", fontsize=10)
    ax = axes[1, 1]
    ax.step(steps[::ku], behind[::ku], where="post", lw=0.8, color="C0")
    ax.set_xlabel("twin step")
    ax.set_ylabel("source steps not yet learned")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    finite = behind[np.isfinite(behind)]
    ax.set_ylim(-0.5, max(float(finite.max()) if finite.size else 0.0, 1.0) + 0.5)
    ax.set_title("learning lag (twin step − source step learned through)", fontsize=10)
    ax = axes[2, 0]
    learns = update_ms > 0  # log scales: a refit costs orders of magnitude more than a step
    learned = update_ms[learns]
    if learned.size:
        ax.semilogy(steps[learns][::ku], learned[::ku], ".", ms=4, color="C2")
    ax.set_xlabel("twin step")
    ax.set_ylabel("update time (ms, log)")
    ax.set_title("worker's update time per twin step (steps that learned)", fontsize=10)
    ax = axes[2, 1]
    if learned.size:
        low, high = float(learned.min()), float(learned.max())
        bins = np.geomspace(low, high * 1.0001, 30) if high > low else 10
        ax.hist(learned, bins=bins, color="C2")
        ax.set_xscale("log")
    ax.set_xlabel("update time (ms, log)")
    ax.set_ylabel("twin steps")
    ax.set_title("update time distribution (steps that learned)", fontsize=10)
    for n, ax in enumerate(axes.flat):
        ax.grid(alpha=GRID_ALPHA)
        if not twin_d.size:
            _no_data(ax, "no committed twin steps")
        elif n >= 2 and not steps.size:
            _no_data(ax, "no update lines (a record before format 5)")
    fig.suptitle(f"Updatable site {twin}: the twin of {source}, learned online", fontsize=11)
    fig.tight_layout()
    return png_bytes(fig)


def correction(site: str, steps: np.ndarray, corrections: np.ndarray, residual: np.ndarray,
               converged: np.ndarray, tolerance: float | None,
               max_iterations: int | None) -> bytes:
    """A site's displacement correction in two panels: how many corrections its trials needed
    (a histogram over whole numbers, the warning threshold at half of ``max_iterations``) and
    per step the residual |target − measured| left after them, with the tolerance line and the
    trials that did not converge in red."""
    fig = Figure(figsize=(9.6, 3.8))
    ax_n, ax_r = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 2]})
    top = int(max(corrections.max(initial=0), max_iterations or 0))
    counts = np.bincount(corrections.astype(np.int64), minlength=top + 1)
    ax_n.bar(np.arange(top + 1), counts, width=0.8, color="C0")
    if max_iterations is not None:
        ax_n.axvline(max_iterations / 2, color="tab:orange", lw=0.8, ls=":",
                     label="warning: over half of max_iterations")
    ax_n.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax_n.set_xlabel("corrections in the trial")
    ax_n.set_ylabel("trials")
    ax_n.set_title("corrections per trial", fontsize=10)
    k = plot_stride(steps.size)
    ok = converged.astype(bool)
    ax_r.plot(steps[ok][::k], residual[ok][::k], ".", ms=2.5, color="C0", label="converged")
    if (~ok).any():
        ax_r.plot(steps[~ok], residual[~ok], "x", ms=5, color="tab:red", label="not converged")
    if tolerance is not None:
        ax_r.axhline(tolerance, color="tab:red", lw=0.8, ls="--", label="tolerance")
    ax_r.set_xlabel("step")
    ax_r.set_ylabel("|target − measured| after (mm)")
    ax_r.set_title("residual error per step", fontsize=10)
    if not steps.size:
        _no_data(ax_r, "no correction lines")
    for ax in (ax_n, ax_r):
        ax.grid(alpha=GRID_ALPHA)
        _legend(ax)
    fig.suptitle(f"{site}: displacement correction", fontsize=SUPTITLE_SIZE)
    fig.tight_layout()
    return png_bytes(fig)
