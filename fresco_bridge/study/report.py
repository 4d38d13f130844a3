"""The study's markdown tables (the paper's Table 3 layout), figures (Figs. 9-14 style) and the
verdicts on the restated updating targets (``study.constants.TARGETS``; BENCHMARKS.md, "Online
updating"), scored per causality with the bad runs named.

matplotlib (Agg) is imported inside :func:`write_figures` only.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from fresco_bridge.study.constants import (
    BOUNDED_PEAK_RATIO,
    TARGET_BASELINE,
    TARGET_LAYOUT,
    TARGET_SUBJECT,
    TARGETS,
    TargetSpec,
)
from fresco_bridge.study.simulate import CaseHistory

__all__ = [
    "RunCheck",
    "describe_target",
    "markdown_tables",
    "score_targets",
    "summary_table",
    "targets_markdown",
    "write_figures",
]


def _f(value: float | None) -> str:
    return "—" if value is None else f"{value:.3f}"


_CAUSALITY = {
    "same-step": "the twin's step i learned from the tested damper's step i",
    "previous-step": "the twin's step i knew the tested damper through step i-1",
}


def markdown_tables(document: Mapping[str, Any]) -> str:
    """Both layouts of one run as markdown, one table each, the paper's rows and columns."""
    head = (f"Run: record {document['record']}, specimen {document['specimen']}, noise "
            f"{document['noise_pct']:g} % ({document['noise_std_kN']:.3f} kN), seed "
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
            sd = "/".join(f"{v:.3f}" for v in m["maesd"])
            parts.append(
                f"| {case} | + | {_f(m['pv_es_pos'])} | {_f(m['pv_ums_pos'])} | "
                f"{_f(m['aepv_pos'])} | {_f(m['maeth'])} | {_f(m['rmseth'])} | "
                f"{_f(m['one_step_rmse'])} | {sd} | {_f(ms['median'])}/{_f(ms['p99'])} |\n"
                f"|  | − | {_f(m['pv_es_neg'])} | {_f(m['pv_ums_neg'])} | {_f(m['aepv_neg'])} "
                f"|  |  |  |  |  |\n"
            )
    return "".join(parts)


def write_figures(
    document: Mapping[str, Any], histories: Mapping[str, Mapping[str, CaseHistory]], out: Path
) -> list[Path]:
    """Hysteresis overlays, force-error histories and bar charts; returns the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written: list[Path] = []
    for layout, cases in histories.items():
        names = list(cases)
        truth_of = ("tested_force" if layout == "paper" else "twin_true_force")
        cols = min(4, len(names))
        rows = -(-len(names) // cols)
        fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.2 * rows), squeeze=False)
        for ax, name in zip(axes.flat, names, strict=False):
            h = cases[name]
            ax.plot(h.twin_drift, getattr(h, truth_of), lw=0.7, color="0.4", label="true")
            ax.plot(h.twin_drift, h.twin_force, lw=0.7, color="C3", label="twin")
            ax.set_title(name, fontsize=9)
            ax.set_xlabel("drift (mm)", fontsize=8)
            ax.set_ylabel("force (kN)", fontsize=8)
            ax.grid(alpha=0.3)
        for ax in list(axes.flat)[len(names):]:
            ax.set_visible(False)
        axes.flat[0].legend(fontsize=7)
        fig.suptitle(f"{layout} layout: twin hysteresis, predicted vs true", fontsize=10)
        fig.tight_layout()
        path = out / f"hysteresis_{layout}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        written.append(path)

        fig, ax = plt.subplots(figsize=(9, 3.6))
        for name in names:
            if name == "reference":
                continue
            h = cases[name]
            time = np.arange(h.twin_force.size) * 0.01
            ax.plot(time, np.abs(getattr(h, truth_of) - h.twin_force), lw=0.7, label=name)
        ax.set_yscale("log")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("|force error| (kN)")
        ax.set_title(f"{layout} layout: absolute force error of the twin (Fig. 13a)")
        ax.legend(fontsize=7, ncol=3)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        path = out / f"force_error_{layout}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        written.append(path)

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4))
    layouts = list(document["layouts"])
    names = [n for n in document["layouts"][layouts[0]]["cases"] if n != "reference"]
    x = np.arange(len(names))
    width = 0.8 / len(layouts)
    for i, layout in enumerate(layouts):
        body = document["layouts"][layout]["cases"]
        ax1.bar(x + i * width, [body[n]["maeth"] for n in names], width, label=layout)
        for story in range(2):
            ax2.bar(x + (2 * i + story) * width / 2, [body[n]["maesd"][story] for n in names],
                    width / 2, label=f"{layout} story {story + 1}")  # fmt: skip
    for ax, title, unit in ((ax1, "MAETH (Fig. 13c)", "kN"), (ax2, "MAESD (Fig. 14)", "mm")):
        ax.set_xticks(x + 0.4 - width / 2, names, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(unit)
        ax.set_title(title)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    path = out / "bars.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    written.append(path)
    return written


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
        maeths = " / ".join(f"{gen[c]['maeth']:.3f}" if c in gen else "–" for c in _SHORT)
        reduction = rms_reduction = "–"
        if TARGET_SUBJECT in gen and TARGET_BASELINE in gen:
            reduction = f"{_reduction(gen, 'maeth'):.1f} %"
            rms_reduction = f"{_reduction(gen, 'rmseth'):.1f} %"
        covering = [s for s in TARGETS if s.kind == "reduction" and _applies(s, doc)]
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


def _applies(spec: TargetSpec, doc: Mapping[str, Any]) -> bool:
    return (spec.specimen in (None, doc["specimen"])
            and spec.noise_pct in (None, float(doc["noise_pct"])))  # fmt: skip


def _check_run(spec: TargetSpec, doc: Mapping[str, Any]) -> RunCheck | None:
    """``spec`` on one run it applies to; None when the run lacks a case the target needs."""
    gen = doc["layouts"][TARGET_LAYOUT]["cases"]
    needs = {"reduction": TARGET_BASELINE, "below": spec.rival, "bounded": TARGET_SUBJECT}
    if TARGET_SUBJECT not in gen or needs[spec.kind] not in gen:
        return None
    mine = gen[TARGET_SUBJECT]
    if spec.kind == "reduction":
        values = [(metric, goal, _reduction(gen, metric)) for metric, goal in spec.reductions]
        figure = ", ".join(f"{metric.upper()} {value:.1f} % below" for metric, _, value in values)
        return RunCheck(all(value >= goal for _, goal, value in values), figure, values[0][2])
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
    if spec.kind == "below":
        return f"MAETH below {spec.rival} on every run"
    if spec.kind == "bounded":
        return (f"bounded on every run (finite, peak |twin force| ≤ {BOUNDED_PEAK_RATIO:g}× the "
                "peak true force)")
    where = spec.specimen or "every specimen"
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
            if not any(s.kind == "reduction" and _applies(s, doc) for s in TARGETS)
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
