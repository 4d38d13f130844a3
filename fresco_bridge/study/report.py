"""The study's markdown tables (the paper's Table 3 layout), figures (Figs. 9-14 style) and the
verdicts on the restated updating targets (``study.constants.TARGETS``; BENCHMARKS.md, "Online
updating"), scored per causality with the bad runs named.

matplotlib loads only when a figure is drawn (``fresco_bridge.report.figures``, the shared
styles; no pyplot state).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from fresco_bridge.integrator import DEMO_DT as STEP_S
from fresco_bridge.numbers import fmt, pct
from fresco_bridge.study.constants import (
    BOUNDED_PEAK_RATIO,
    TARGET_BASELINE,
    TARGET_LAYOUT,
    TARGET_SUBJECT,
    TARGETS,
    TargetSpec,
)
from fresco_bridge.study.simulate import CaseHistory

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "RunCheck",
    "bars_figure",
    "describe_target",
    "force_error_figure",
    "hysteresis_figure",
    "markdown_tables",
    "score_targets",
    "summary_table",
    "targets_markdown",
    "write_figures",
]


_CAUSALITY = {
    "same-step": "the twin's step i learned from the tested damper's step i",
    "previous-step": "the twin's step i knew the tested damper through step i-1",
}


def markdown_tables(document: Mapping[str, Any]) -> str:
    """Both layouts of one run as markdown, one table each, the paper's rows and columns."""
    head = (f"Run: record {document['record']}, specimen {document['specimen']}, noise "
            f"{document['noise_pct']:g} % ({fmt(document['noise_std_kN'], 'kN')}), seed "
            f"{document['seed']}, {document['steps']} steps, causality "
            f"{document['causality']} ({_CAUSALITY[document['causality']]})\n")  # fmt: skip
    parts = [head]
    for layout, body in document["layouts"].items():
        parts.append(f"\n### {layout} layout (scored against the {body['scored_against']})\n")
        parts.append(
            "\n| Case | Peak | PVES (kN) | PVUMS (kN) | AEPV (kN) | MAETH (kN) | RMSETH (kN) | "
            "one-step RMSE (kN) | MAESD s1/s2 (mm) | update ms median/p99 |\n"
            "|---|---|---|---|---|---|---|---|---|---|\n"
        )
        for case, m in body["cases"].items():
            ms = m["update_time_ms"]
            sd = "/".join(fmt(v) for v in m["maesd"])
            parts.append(
                f"| {case} | + | {fmt(m['pv_es_pos'])} | {fmt(m['pv_ums_pos'])} | "
                f"{fmt(m['aepv_pos'])} | {fmt(m['maeth'])} | {fmt(m['rmseth'])} | "
                f"{fmt(m['one_step_rmse'])} | {sd} | {fmt(ms['median'])}/{fmt(ms['p99'])} |\n"
                f"|  | − | {fmt(m['pv_es_neg'])} | {fmt(m['pv_ums_neg'])} | {fmt(m['aepv_neg'])} "
                f"|  |  |  |  |  |\n"
            )
    return "".join(parts)


def write_figures(
    document: Mapping[str, Any], histories: Mapping[str, Mapping[str, CaseHistory]], out: Path
) -> list[Path]:
    """Per layout the hysteresis grid and the force-error small multiples, then the bar charts
    of every layout; returns the files written (PNG)."""
    from fresco_bridge.report.figures import DPI

    written: list[Path] = []
    for layout, cases in histories.items():
        truth_of = "tested_force" if layout == "paper" else "twin_true_force"
        for name, fig in ((f"hysteresis_{layout}.png", hysteresis_figure(layout, cases, truth_of)),
                          (f"force_error_{layout}.png",
                           force_error_figure(layout, cases, truth_of, document))):
            path = out / name
            fig.savefig(path, dpi=DPI)
            written.append(path)
    path = out / "bars.png"
    bars_figure(document).savefig(path, dpi=DPI)
    written.append(path)
    return written


def hysteresis_figure(layout: str, cases: Mapping[str, CaseHistory], truth_of: str) -> Figure:
    """Every case's twin hysteresis, predicted over true, one panel each (own scales: a case
    that diverges must not flatten the others)."""
    from fresco_bridge.report.figures import (
        PREDICTION,
        SUPTITLE_SIZE,
        TRUTH,
        panel_grid,
        style_panel,
    )

    fig, axes = panel_grid(len(cases))
    for ax, (name, h) in zip(axes, cases.items(), strict=True):
        ax.plot(h.twin_drift, getattr(h, truth_of), label="true", **TRUTH)
        ax.plot(h.twin_drift, h.twin_force, label="twin", **PREDICTION)
        style_panel(ax, name, "drift (mm)", "force (kN)")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{layout} layout: twin hysteresis, predicted vs true", fontsize=SUPTITLE_SIZE)
    fig.tight_layout()
    return fig


def force_error_figure(layout: str, cases: Mapping[str, CaseHistory], truth_of: str,
                      document: Mapping[str, Any]) -> Figure:
    """|true − twin force| in time, one panel per learning case on shared axes (log force), the
    targets' baseline case (``TARGET_BASELINE``) in grey behind every other so each panel reads
    as better or worse than it, each panel's MAETH and RMSETH in its corner (Fig. 13a)."""
    from matplotlib.lines import Line2D

    from fresco_bridge.report.figures import (
        LABEL_SIZE,
        PREDICTION,
        SUPTITLE_SIZE,
        TRUTH,
        _no_data,
        outer_labels,
        panel_grid,
        style_panel,
    )

    names = [n for n in cases if n != "reference"]
    if not names:  # a study of the reference alone: its error is zero by construction
        fig, axes = panel_grid(1)
        _no_data(axes[0], "no learning case in this study (the reference's error is zero)")
        return fig
    errors = {n: np.abs(getattr(cases[n], truth_of) - cases[n].twin_force) for n in names}
    metrics = document["layouts"].get(layout, {}).get("cases", {})
    fig, axes = panel_grid(len(names), cols=3, sharex=True, sharey=True, size=(4.0, 2.6))
    for ax, name in zip(axes, names, strict=True):
        time = np.arange(errors[name].size) * STEP_S
        if TARGET_BASELINE in errors and name != TARGET_BASELINE:
            bench = errors[TARGET_BASELINE]
            ax.plot(np.arange(bench.size) * STEP_S, bench,
                    **{**TRUTH, "lw": 0.5, "color": "0.65"})
        ax.plot(time, errors[name], **PREDICTION)
        ax.set_yscale("log")
        style_panel(ax, name, "time (s)", "|force error| (kN)")
        if name in metrics:
            m = metrics[name]
            ax.text(0.02, 0.96, f"MAETH {_sig(m['maeth'])} kN\nRMSETH {_sig(m['rmseth'])} kN",
                    transform=ax.transAxes, va="top", fontsize=LABEL_SIZE,
                    bbox={"boxstyle": "round,pad=0.25", "fc": "white", "ec": "0.8", "alpha": 0.85})
    outer_labels(axes, 3)
    positive = np.concatenate([e[e > 0] for e in errors.values()] or [np.ones(1)])
    if positive.size:  # the floor: 6 decades below the worst, not a round-off dip at step 0
        top = float(positive.max())
        axes[0].set_ylim(max(float(positive.min()), top * 1e-6), top * 3.0)
    handles = [(Line2D([], [], **PREDICTION), "the panel's case")]
    if TARGET_BASELINE in errors and len(names) > 1:
        handles.append((Line2D([], [], **{**TRUTH, "color": "0.65"}),
                        f"{TARGET_BASELINE} (for scale)"))
    fig.legend(*zip(*handles, strict=True), loc="lower center", ncol=2, fontsize=LABEL_SIZE,
               frameon=False)
    fig.suptitle(f"{layout} layout: absolute force error of the twin (Fig. 13a), one panel "
                 "per case, shared axes", fontsize=SUPTITLE_SIZE)
    fig.tight_layout(rect=(0.0, 0.04, 1.0, 1.0))
    return fig


def bars_figure(document: Mapping[str, Any]) -> Figure:
    """MAETH and MAESD per case and layout (Figs. 13c, 14) as horizontal bars on log axes with
    their values written at the bar ends: the cases span three decades (a diverged ANN at
    hundreds of kN, ``online_improved`` below 1 kN), which a linear axis flattens to nothing."""
    from fresco_bridge.report.figures import (
        GRID_ALPHA,
        LABEL_SIZE,
        SUPTITLE_SIZE,
        panel_grid,
        style_panel,
    )

    layouts = list(document["layouts"])
    names = [n for n in document["layouts"][layouts[0]]["cases"] if n != "reference"]
    panels = (("MAETH (Fig. 13c)", "kN", "maeth", None),
              ("MAESD story 1 (Fig. 14)", "mm", "maesd", 0),
              ("MAESD story 2 (Fig. 14)", "mm", "maesd", 1))
    fig, axes = panel_grid(len(panels), cols=3, sharey=True,
                           size=(4.0, 0.55 * len(names) * len(layouts) / 2 + 1.4))
    y = np.arange(len(names))
    height = 0.8 / len(layouts)
    for ax, (title, unit, key, index) in zip(axes, panels, strict=True):
        bars = []
        for i, layout in enumerate(layouts):
            body = document["layouts"][layout]["cases"]
            v = np.array([float(body[n][key] if index is None else body[n][key][index])
                          for n in names])
            bars.append((y - 0.4 + (i + 0.5) * height, v, layout))
        every = np.concatenate([v for _, v, _ in bars])
        positive = every[np.isfinite(every) & (every > 0)]
        low, high = (float(positive.min()), float(positive.max())) if positive.size else (1, 1)
        base = low / 3.0  # bars start at the axis (a log axis has no zero)
        for i, (pos, v, layout) in enumerate(bars):
            ax.barh(pos, np.where(v > 0, v, np.nan) - base, height, left=base, color=f"C{i}",
                    label=f"{layout} layout")
            for p, value in zip(pos, v, strict=True):  # no bar for 0 or NaN: the label says so
                ax.text(value if math.isfinite(value) and value > 0 else base, p,
                        f" {_sig(value)}", va="center", fontsize=LABEL_SIZE)
        ax.set_xscale("log")
        ax.set_xlim(base, high * 12.0)  # room for the value labels right of the bars
        style_panel(ax, title, f"{unit} (log scale)", "")
        ax.grid(alpha=GRID_ALPHA, axis="x", which="both")
        ax.grid(False, axis="y")
    axes[0].set_yticks(y, names, fontsize=LABEL_SIZE)
    axes[0].invert_yaxis()  # the cases in the tables' order, top to bottom
    fig.legend(*axes[0].get_legend_handles_labels(), loc="lower center", ncol=len(layouts),
               fontsize=LABEL_SIZE, frameon=False)
    fig.suptitle("errors of the twin per case, smaller is better (log axes: every case legible)",
                 fontsize=SUPTITLE_SIZE)
    fig.tight_layout(rect=(0.0, 0.06, 1.0, 1.0))
    return fig


def _sig(value: float) -> str:
    """Three significant digits, no float dust (``0.59``, ``37.3``, ``300``)."""
    if not math.isfinite(value):
        return "—"
    return f"{value:.3g}" if abs(value) < 1e4 else f"{value:.3e}"


def summary_table(documents: Sequence[Mapping[str, Any]]) -> str:
    """One row per run: generalisation MAETH of every case, our MAETH and RMSETH reductions, the
    run's (specimen, noise) target and rivals checks (``TARGETS``); the paper layout's MAETH
    ordering beside its one-step-ahead ordering."""
    lines = [
        "| record | specimen | noise % | seed | causality | MAETH generalisation (kN): "
        + " / ".join(_SHORT.values()) + " | online_improved vs calibrated | target | beats "
        "ukf & ann | RMSETH vs calibrated | paper layout MAETH order | paper layout one-step "
        "order |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for doc in documents:
        gen = doc["layouts"][TARGET_LAYOUT]["cases"]
        paper = doc["layouts"]["paper"]["cases"]
        maeths = " / ".join(fmt(gen[c]["maeth"]) if c in gen else "–" for c in _SHORT)
        reduction = rms_reduction = "–"
        if TARGET_SUBJECT in gen and TARGET_BASELINE in gen:
            reduction = pct(_reduction(gen, "maeth"), 1)
            rms_reduction = pct(_reduction(gen, "rmseth"), 1)
        covering = [s for s in TARGETS if _covers(s, doc)]
        target = _run_mark([_check_run(s, doc) for s in covering]) if covering else "no target"
        beats = _run_mark([_check_run(s, doc) for s in TARGETS if s.kind == "below"])
        learning = [c for c in paper if c != "reference"]
        by_maeth = " < ".join(_SHORT[c] for c in sorted(learning, key=lambda c: paper[c]["maeth"]))
        by_step = " < ".join(_SHORT[c] for c in sorted(learning,
                                                        key=lambda c: paper[c]["one_step_rmse"]))
        lines.append(f"| {doc['record']} | {doc['specimen']} | {doc['noise_pct']:g} | "
                     f"{doc['seed']} | {doc['causality']} | {maeths} | {reduction} | {target} | "
                     f"{beats} | {rms_reduction} | {by_maeth} | {by_step} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def _run_mark(checks: Sequence[RunCheck | None]) -> str:
    """One run's cell: met when every check that ran is met; – when none ran."""
    ran = [c for c in checks if c is not None]
    return "–" if not ran else ("met" if all(c.met for c in ran) else "**missed**")


class RunCheck(NamedTuple):
    """One target on one run: met or not, the figure that says why, and the first reduction
    (% below the baseline) for a median rule."""

    met: bool
    figure: str
    reduction_pct: float | None = None


def _reduction(gen: Mapping[str, Any], metric: str) -> float:
    """How far (%) the subject's ``metric`` is below the baseline's (NaN with no baseline)."""
    base = float(gen[TARGET_BASELINE][metric])
    return 100.0 * (1.0 - float(gen[TARGET_SUBJECT][metric]) / base) if base > 0 else math.nan


def _specimens(spec: TargetSpec) -> tuple[str, ...] | None:
    """The specimens ``spec`` applies to (None: every one)."""
    return (spec.specimen,) if isinstance(spec.specimen, str) else spec.specimen


def _applies(spec: TargetSpec, doc: Mapping[str, Any]) -> bool:
    specimens = _specimens(spec)
    return ((specimens is None or doc["specimen"] in specimens)
            and spec.noise_pct in (None, float(doc["noise_pct"])))  # fmt: skip


def _covers(spec: TargetSpec, doc: Mapping[str, Any]) -> bool:
    """Whether ``spec`` is the accuracy target of ``doc``'s (specimen, noise): a ``reduction``
    (out of family) or ``no-harm`` (in family) target that applies to it."""
    return spec.kind in ("reduction", "no-harm") and _applies(spec, doc)


def _check_run(spec: TargetSpec, doc: Mapping[str, Any]) -> RunCheck | None:
    """``spec`` on one run it applies to; None when the run lacks a case the target needs."""
    gen = doc["layouts"][TARGET_LAYOUT]["cases"]
    needs = {"reduction": TARGET_BASELINE, "below": spec.rival, "no-harm": TARGET_BASELINE,
             "bounded": TARGET_SUBJECT}
    if TARGET_SUBJECT not in gen or needs[spec.kind] not in gen:
        return None
    mine = gen[TARGET_SUBJECT]
    if spec.kind == "reduction":
        values = [(metric, goal, _reduction(gen, metric)) for metric, goal in spec.reductions]
        figure = ", ".join(f"{metric.upper()} {value:.1f} % below" for metric, _, value in values)
        return RunCheck(all(value >= goal for _, goal, value in values), figure, values[0][2])
    if spec.kind == "no-harm" and spec.max_ratio is not None:
        base = float(gen[TARGET_BASELINE]["maeth"])
        ratio = float(mine["maeth"]) / base if base > 0.0 else math.inf
        return RunCheck(float(mine["maeth"]) <= spec.max_ratio * base,
                        f"MAETH {mine['maeth']:.4f} kN, {TARGET_BASELINE} {base:.4f} kN "
                        f"(×{ratio:.3f})")
    if spec.kind == "below" and spec.rival is not None:
        theirs = gen[spec.rival]["maeth"]
        return RunCheck(mine["maeth"] < theirs,
                        f"MAETH {mine['maeth']:.3f} kN, {spec.rival} {theirs:.3f} kN")
    peak_twin = max(mine["pv_ums_pos"], mine["pv_ums_neg"])
    peak_true = max(mine["pv_es_pos"], mine["pv_es_neg"])
    finite = all(math.isfinite(v) for v in (mine["maeth"], mine["rmseth"], peak_twin))
    return RunCheck(finite and peak_twin <= BOUNDED_PEAK_RATIO * peak_true,
                    f"peak |twin force| {peak_twin:.3f} kN, true {peak_true:.3f} kN")


def describe_target(spec: TargetSpec) -> str:
    """The target in words, from its spec."""
    specimens = _specimens(spec)
    where = "every specimen" if specimens is None else ", ".join(specimens)
    if spec.kind == "below":
        return f"{where}: MAETH below {spec.rival} on every run"
    if spec.kind == "no-harm":
        return f"{where} (in family): MAETH ≤ {spec.max_ratio:g}× {TARGET_BASELINE}'s on every run"
    if spec.kind == "bounded":
        return (f"bounded on every run (finite, peak |twin force| ≤ {BOUNDED_PEAK_RATIO:g}× the "
                "peak true force)")
    if spec.noise_pct is not None:
        where += f", {spec.noise_pct:g} % noise"
    text = f"{where}: " + " and ".join(f"{m.upper()} ≥ {goal:g} %" for m, goal in spec.reductions)
    text += " below" + (" on every run" if spec.median_pct is not None else "")
    if spec.median_pct is not None:
        text += f", median over the runs ≥ {spec.median_pct:g} %"
    return text


def _score(spec: TargetSpec, documents: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """One target over one causality's runs: verdict, runs meeting it, the bad runs named."""
    checked = [(doc, check) for doc in documents if _applies(spec, doc)
               for check in [_check_run(spec, doc)] if check is not None]  # fmt: skip
    entry: dict[str, Any] = {
        "target": spec.name,
        "text": describe_target(spec),
        "runs": len(checked),
        "meeting": sum(check.met for _, check in checked),
        "bad": [{"record": doc["record"], "specimen": doc["specimen"],
                 "noise_pct": doc["noise_pct"], "seed": doc["seed"],
                 "causality": doc["causality"], "figure": check.figure}
                for doc, check in checked if not check.met],
    }  # fmt: skip
    median_met = True
    if spec.median_pct is not None:
        values = [check.reduction_pct for _, check in checked if check.reduction_pct is not None]
        entry["median_pct"] = float(np.median(values)) if values else None
        median_met = bool(values) and float(np.median(values)) >= spec.median_pct
    met = entry["meeting"] == entry["runs"] and median_met
    entry["verdict"] = "not run" if not checked else ("met" if met else "missed")
    return entry


def score_targets(documents: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Every target of ``TARGETS`` per causality (summary.json's ``targets``): a verdict (met,
    missed, not run), the count of runs meeting it and the bad runs; and the (specimen, noise)
    pairs run that no target covers."""
    by_causality: dict[str, Any] = {}
    for causality in dict.fromkeys(doc["causality"] for doc in documents):
        runs = [doc for doc in documents if doc["causality"] == causality]
        uncovered = Counter(
            (doc["specimen"], float(doc["noise_pct"])) for doc in runs
            if not any(_covers(s, doc) for s in TARGETS)
        )  # fmt: skip
        by_causality[causality] = {
            "runs": len(runs),
            "targets": [_score(spec, runs) for spec in TARGETS],
            "no_target": [{"specimen": specimen, "noise_pct": noise, "runs": n}
                          for (specimen, noise), n in uncovered.items()],
        }  # fmt: skip
    return {"subject": TARGET_SUBJECT, "layout": TARGET_LAYOUT, "baseline": TARGET_BASELINE,
            "bounded_peak_ratio": BOUNDED_PEAK_RATIO, "by_causality": by_causality}  # fmt: skip


def targets_markdown(targets: Mapping[str, Any]) -> str:
    """The verdicts of :func:`score_targets` as markdown: per causality, one line a target, a
    sub-line per bad run."""
    lines = [f"## Targets: {targets['subject']}, {targets['layout']} layout, against "
             f"{targets['baseline']} (BENCHMARKS.md, \"Online updating\")"]  # fmt: skip
    for causality, body in targets["by_causality"].items():
        lines += ["", f"### causality {causality} ({body['runs']} run(s))", ""]
        for entry in body["targets"]:
            verdict = {"missed": "**missed**"}.get(entry["verdict"], entry["verdict"])
            line = f"- {entry['text']}: {verdict}"
            if entry["runs"]:
                line += f", {entry['meeting']} of {entry['runs']} run(s)"
            if entry.get("median_pct") is not None:
                line += f", median {entry['median_pct']:.1f} %"
            lines.append(line)
            lines += [f"  - bad: {b['record']}, {b['specimen']}, {b['noise_pct']:g} % noise, seed "
                      f"{b['seed']}, {b['causality']}: {b['figure']}" for b in entry["bad"]]
        lines += [f"- {n['specimen']}, {n['noise_pct']:g} % noise: no target ({n['runs']} run(s))"
                  for n in body["no_target"]]  # fmt: skip
    return "\n".join(lines) + "\n"


_SHORT = {
    "conventional_paper": "conv_paper",
    "conventional_calibrated": "conv_cal",
    "offline_ann": "off_ann",
    "online_ukf": "ukf",
    "online_ann": "ann",
    "online_improved": "improved",
}
