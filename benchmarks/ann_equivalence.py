"""online_ann's default: is "8 it f32" as accurate as the paper's fit? A pre-registered test.

It decided ``online_ann``'s default (``max_iterations=8, single_precision_hessian=true``, the
``"8 it f32"`` of ``bench_online_ann.VARIANTS``) against the paper's 50-iteration fit: 28 pairs
(synthetic records 2..15 x ``bwbn``, ``menegotto-pinto``; 400 steps; generalisation layout, the
paper layout reported beside but not decided on), online seeds 1-3. The rule, fixed before any
run: per endpoint (teacher-forced RMSE, MAETH) and pair, d_p = mean over seeds of ln(candidate)
- ln(faithful); the candidate is non-inferior iff the one-sided 95 % upper bound
d + t(0.95, n-1) s / sqrt(n) <= ln 1.25; "equal accuracy" iff both endpoints are. Each run's row
is appended to ``--out`` (JSONL) as it finishes; a re-run resumes; ``--analyse-only`` analyses
the file (partial data gives no verdict).

    nice -n 10 .venv/bin/python -m benchmarks.ann_equivalence [--quick] --workers 2 --out F.jsonl

Feeds BENCHMARKS.md, "Online updating". ``--quick``: one pair, one seed, 40 steps, into a
temporary file (partial: no verdict), a smoke run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats  # type: ignore[import-untyped]

from benchmarks.bench_online_ann import VARIANTS, Pair, machine, prepare, scored_run
from fresco_bridge.sweeps import run_sweep
from fresco_bridge.updating import make_updater
from fresco_bridge.updating.ann import AnnModel

FAITHFUL = "faithful (50 it)"
CANDIDATE = "8 it f32"
METHODS = (FAITHFUL, CANDIDATE)
ENDPOINTS = ("teacher_forced_rmse", "maeth")  # primary, co-primary
MARGIN = 1.25  # non-inferior iff the one-sided 95 % upper bound of the ratio <= 1.25
RUNAWAY_KN = 20.0
SPECIMENS = ("bwbn", "menegotto-pinto")
RECORDS = tuple(range(2, 16))
SEEDS = (1, 2, 3)
PAPER_SEED = 1

Key = tuple[str, str, str, int]  # layout, pair, method, seed


def run_key(row: Mapping[str, Any]) -> Key:
    return (str(row["layout"]), str(row["pair"]), str(row["method"]), int(row["seed"]))


# --- analysis (pure) ------------------------------------------------------------------------


def _ln(value: float, what: str) -> float:
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{what}: {value!r} is not a positive finite number")
    return math.log(value)


def _specimen(pair: str) -> str:
    return pair.split("/")[0]


Table = dict[str, dict[str, dict[int, Mapping[str, Any]]]]


def _table(rows: Iterable[Mapping[str, Any]], layout: str) -> Table:
    """pair -> method -> seed -> row, for one layout."""
    out: Table = {}
    for row in rows:
        if row["layout"] == layout:
            out.setdefault(str(row["pair"]), {}).setdefault(str(row["method"]), {})[
                int(row["seed"])] = row
    return out


def _geo(values: Sequence[float]) -> float:
    return math.exp(float(np.mean(values))) if values else math.nan


def non_inferiority(d: Mapping[str, float], margin: float = MARGIN) -> dict[str, Any]:
    """The rule on per-pair log differences d_p = L_C - L_F (candidate minus faithful)."""
    pairs = sorted(d)
    vals = np.array([d[p] for p in pairs], dtype=np.float64)
    n = len(vals)
    dbar = float(np.mean(vals)) if n else math.nan
    s = float(np.std(vals, ddof=1)) if n >= 2 else math.nan
    t = float(stats.t.ppf(0.95, n - 1)) if n >= 2 else math.nan
    upper = dbar + t * s / math.sqrt(n) if n >= 2 else math.nan
    by_spec: dict[str, list[float]] = {}
    for p in pairs:
        by_spec.setdefault(_specimen(p), []).append(d[p])
    worst = sorted(pairs, key=lambda p: d[p], reverse=True)[:3]
    return {
        "n": n, "d_mean": dbar, "d_sd": s, "t_0.95": t, "upper": upper,
        "margin_ln": math.log(margin),
        "ratio": math.exp(dbar) if n else math.nan,
        "ratio_upper": math.exp(upper) if n >= 2 else math.nan,
        "non_inferior": bool(upper <= math.log(margin)) if n >= 2 else None,
        "pairs_worse": sum(1 for v in vals if v > 0.0),
        "pairs_worse_list": [p for p in pairs if d[p] > 0.0],
        "per_specimen_ratio": {k: _geo(v) for k, v in sorted(by_spec.items())},
        "per_specimen_n": {k: len(v) for k, v in sorted(by_spec.items())},
        "worst3": [{"pair": p, "ratio": math.exp(d[p])} for p in worst],
    }


def analyse(rows: Sequence[Mapping[str, Any]], seeds: Sequence[int] = SEEDS,
            expected_pairs: int = len(RECORDS) * len(SPECIMENS),
            paper_seed: int = PAPER_SEED) -> dict[str, Any]:
    """The pre-registered analysis of the run rows (dicts with layout, pair, method, seed and
    the endpoints). A pair enters the test only with every seed of both methods; the verdict is
    given only when all ``expected_pairs`` are complete."""
    gen = _table(rows, "generalisation")
    complete = sorted(p for p, m in gen.items()
                      if all(set(seeds) <= set(m.get(meth, {})) for meth in METHODS))
    out: dict[str, Any] = {"pairs_complete": len(complete), "pairs_expected": expected_pairs,
                           "partial": len(complete) < expected_pairs,
                           "seeds": list(seeds), "endpoints": {}}
    for e in ENDPOINTS:
        lf = {p: float(np.mean([_ln(float(gen[p][FAITHFUL][s][e]), f"{p} {FAITHFUL} {s} {e}")
                                for s in seeds])) for p in complete}
        lc = {p: float(np.mean([_ln(float(gen[p][CANDIDATE][s][e]), f"{p} {CANDIDATE} {s} {e}")
                                for s in seeds])) for p in complete}
        res = non_inferiority({p: lc[p] - lf[p] for p in complete})
        by_spec: dict[str, tuple[list[float], list[float]]] = {}
        for p in complete:
            f_, c_ = by_spec.setdefault(_specimen(p), ([], []))
            f_.append(lf[p])
            c_.append(lc[p])
        res["per_specimen_geomean"] = {k: {FAITHFUL: _geo(f_), CANDIDATE: _geo(c_)}
                                       for k, (f_, c_) in sorted(by_spec.items())}
        res["geomean"] = {FAITHFUL: _geo(list(lf.values())), CANDIDATE: _geo(list(lc.values()))}
        # the faithful method's own spread: only its random offline rows change
        spread: dict[str, Any] = {}
        for meth in METHODS:
            logs = {p: [_ln(float(gen[p][meth][s][e]), p) for s in seeds] for p in complete}
            sds = [float(np.std(v, ddof=1)) for v in logs.values()] if len(seeds) >= 2 else []
            ratios = {}
            for j in range(1, len(seeds)):
                dj = [v[j] - v[0] for v in logs.values()]
                ratios[f"seed {seeds[j]} / seed {seeds[0]}"] = {
                    "ratio": _geo(dj), "pairs_up": sum(1 for x in dj if x > 0.0),
                    "min": math.exp(min(dj)) if dj else math.nan,
                    "max": math.exp(max(dj)) if dj else math.nan}
            spread[meth] = {
                "sd_ln_median": float(np.median(sds)) if sds else math.nan,
                "sd_ln_min": min(sds) if sds else math.nan,
                "sd_ln_max": max(sds) if sds else math.nan,
                "sd_ln_mean": float(np.mean(sds)) if sds else math.nan,
                "seed_ratios": ratios}
        res["spread"] = spread
        out["endpoints"][e] = res
    nis = [out["endpoints"][e]["non_inferior"] for e in ENDPOINTS]
    out["equal_accuracy"] = None if out["partial"] or None in nis else all(nis)
    out["runaways"] = {
        layout: {meth: {"runs_over": sum(1 for r in rows if r["layout"] == layout
                                         and r["method"] == meth
                                         and not float(r["maeth"]) <= RUNAWAY_KN),
                        "runs": sum(1 for r in rows if r["layout"] == layout
                                    and r["method"] == meth)}
                 for meth in METHODS}
        for layout in ("generalisation", "paper")}
    paper = _table(rows, "paper")
    pp = sorted(p for p, m in paper.items()
                if all(paper_seed in m.get(meth, {}) for meth in METHODS))
    pres: dict[str, Any] = {"pairs_complete": len(pp)}
    for e in ENDPOINTS:
        f_ = [float(paper[p][FAITHFUL][paper_seed][e]) for p in pp]
        c_ = [float(paper[p][CANDIDATE][paper_seed][e]) for p in pp]
        d = [_ln(c, p) - _ln(f, p) for p, f, c in zip(pp, f_, c_, strict=True)]
        pres[e] = {"median": {FAITHFUL: float(np.median(f_)) if f_ else math.nan,
                              CANDIDATE: float(np.median(c_)) if c_ else math.nan},
                   "ratio": _geo(d), "pairs_worse": sum(1 for x in d if x > 0.0),
                   "worst3": [{"pair": p, "ratio": math.exp(x)} for x, p in
                              sorted(zip(d, pp, strict=True), reverse=True)[:3]]}
    out["paper"] = pres
    timing: dict[str, Any] = {}
    for meth in METHODS:
        rs = [r for r in rows if r["method"] == meth]
        if rs:
            timing[meth] = {
                "runs": len(rs),
                "cpu_ms_median_median": float(np.median([r["cpu_ms_median"] for r in rs])),
                "cpu_ms_median_range": [min(r["cpu_ms_median"] for r in rs),
                                        max(r["cpu_ms_median"] for r in rs)],
                "cpu_ms_p99_median": float(np.median([r["cpu_ms_p99"] for r in rs])),
                "cpu_ms_p99_max": max(r["cpu_ms_p99"] for r in rs),
                "iterations_mean": float(np.mean([r["iterations_mean"] for r in rs]))}
    out["timing"] = timing
    return out


def markdown(summary: Mapping[str, Any]) -> str:
    """The summary as markdown tables."""
    names = {"teacher_forced_rmse": "teacher-forced RMSE (primary)", "maeth": "MAETH (co-primary)"}
    lines = [f"pairs complete: {summary['pairs_complete']} of {summary['pairs_expected']}"
             + (" (PARTIAL: no verdict)" if summary["partial"] else ""), "",
             "| endpoint | geo-mean ratio 8 it f32 / faithful | one-sided 95 % upper bound | "
             "U vs ln 1.25 | non-inferior | pairs worse | bwbn ratio | Menegotto-Pinto ratio | "
             "worst 3 pairs |",
             "|---|---|---|---|---|---|---|---|---|"]
    for e, res in summary["endpoints"].items():
        spec = res["per_specimen_ratio"]
        lines.append(
            f"| {names.get(e, e)} | ×{res['ratio']:.3f} | ×{res['ratio_upper']:.3f} | "
            f"{res['upper']:.4f} vs {res['margin_ln']:.4f} | "
            f"{ {True: 'yes', False: 'no', None: '–'}[res['non_inferior']] } | "
            f"{res['pairs_worse']}/{res['n']} | ×{spec.get('bwbn', math.nan):.3f} | "
            f"×{spec.get('menegotto-pinto', math.nan):.3f} | "
            + ", ".join(f"{w['pair']} ×{w['ratio']:.2f}" for w in res["worst3"]) + " |")
    verdict = {True: "**equal accuracy declared**", False: "**equal accuracy NOT declared**",
               None: "no verdict (partial data)"}[summary["equal_accuracy"]]
    lines += ["", f"Verdict by the pre-registered rule: {verdict}", "",
              "| endpoint | geo-mean, faithful | geo-mean, 8 it f32 | per specimen (faithful → "
              "8 it f32) |", "|---|---|---|---|"]
    for e, res in summary["endpoints"].items():
        g = res["geomean"]
        per = "; ".join(f"{k} {v[FAITHFUL]:.3f} → {v[CANDIDATE]:.3f}"
                        for k, v in res["per_specimen_geomean"].items())
        lines.append(f"| {names.get(e, e)} | {g[FAITHFUL]:.3f} | {g[CANDIDATE]:.3f} | {per} |")
    lines += ["", "Own spread over online seeds (SD of ln e per pair: median [min–max]; "
              "geo-mean ratio between seeds, pairs up, range):", "",
              "| endpoint | method | SD ln e | seed ratios |", "|---|---|---|---|"]
    for e, res in summary["endpoints"].items():
        for meth, sp in res["spread"].items():
            ratios = "; ".join(f"{k} ×{v['ratio']:.3f} (up on {v['pairs_up']}, "
                               f"×{v['min']:.2f}–×{v['max']:.2f})"
                               for k, v in sp["seed_ratios"].items())
            lines.append(f"| {names.get(e, e)} | {meth} | {sp['sd_ln_median']:.3f} "
                         f"[{sp['sd_ln_min']:.3f}–{sp['sd_ln_max']:.3f}] | {ratios} |")
    lines += ["", "Runaways (MAETH > 20 kN), runs over / runs:", ""]
    for layout, rs in summary["runaways"].items():
        lines.append(f"- {layout}: " + ", ".join(f"{m} {v['runs_over']}/{v['runs']}"
                                                   for m, v in rs.items()))
    pa = summary["paper"]
    lines += ["", f"Paper layout, online seed {PAPER_SEED} ({pa['pairs_complete']} pairs; "
              "secondary):", "",
              "| endpoint | median faithful | median 8 it f32 | geo-mean ratio | pairs worse | "
              "worst 3 |", "|---|---|---|---|---|---|"]
    for e in ENDPOINTS:
        r = pa[e]
        lines.append(f"| {names.get(e, e)} | {r['median'][FAITHFUL]:.4f} | "
                     f"{r['median'][CANDIDATE]:.4f} | ×{r['ratio']:.3f} | "
                     f"{r['pairs_worse']}/{pa['pairs_complete']} | "
                     + ", ".join(f"{w['pair']} ×{w['ratio']:.2f}" for w in r["worst3"]) + " |")
    lines += ["", "Timing (informational; shared machine, nice 10, 2 workers):", ""]
    for meth, tm in summary["timing"].items():
        lines.append(f"- {meth}: {tm['runs']} runs, CPU ms median per update: median of runs "
                     f"{tm['cpu_ms_median_median']:.1f} (range {tm['cpu_ms_median_range'][0]:.1f}"
                     f"–{tm['cpu_ms_median_range'][1]:.1f}), p99 median of runs "
                     f"{tm['cpu_ms_p99_median']:.1f}, max {tm['cpu_ms_p99_max']:.1f}; "
                     f"LM iterations mean {tm['iterations_mean']:.2f}")
    return "\n".join(lines) + "\n"


# --- runs -----------------------------------------------------------------------------------

Task = tuple[Key, AnnModel, Pair]


def one_run(task: Task) -> dict[str, Any]:
    """One replay of one method on one pair (a sweep task: any process)."""
    (layout, label, method, seed), model, pair = task
    t0 = time.perf_counter()
    scores = scored_run(make_updater("online_ann", model=model,
                                     **{**VARIANTS[method], "seed": seed}), pair)
    return {"layout": layout, "pair": label, "method": method, "seed": seed,
            "samples": len(pair.twin_d), **scores,
            "run_s": time.perf_counter() - t0, "pid": os.getpid(),
            "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def planned(specimens: Sequence[str], records: Sequence[int], seeds: Sequence[int],
            paper: bool) -> list[Key]:
    """Generalisation first, pair by pair (so partial data has complete pairs), then paper."""
    keys: list[Key] = []
    for rec in records:
        for spec in specimens:
            for seed in seeds:
                for meth in METHODS:
                    keys.append(("generalisation", f"{spec}/record{rec}", meth, seed))
    if paper:
        for rec in records:
            for spec in specimens:
                for meth in METHODS:
                    keys.append(("paper", f"{spec}/record{rec}", meth, PAPER_SEED))
    return keys


def load(path: Path, steps: int) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    rows = []
    for line in path.read_text().splitlines():
        if line.strip():
            row = json.loads(line)
            if int(row["steps"]) == steps:
                rows.append(row)
    return rows


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"


def _report(args: argparse.Namespace, info: dict[str, Any]) -> None:
    rows = load(args.out, args.steps)
    summary = analyse(rows, seeds=args.seeds,
                      expected_pairs=len(args.records) * len(args.specimens))
    summary["info"] = info
    text = markdown(summary)
    print(text, flush=True)
    stem = args.out.with_suffix("")
    Path(f"{stem}.summary.json").write_text(json.dumps(summary, indent=2))
    Path(f"{stem}.summary.md").write_text(text)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, default=None, help="JSONL of run rows (resumed)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--specimens", default=",".join(SPECIMENS))
    p.add_argument("--records", default=",".join(map(str, RECORDS)))
    p.add_argument("--seeds", default=",".join(map(str, SEEDS)))
    p.add_argument("--steps", type=int, default=400)
    p.add_argument("--pretrain-iterations", type=int, default=300)
    p.add_argument("--no-paper", action="store_true", help="skip the paper layout")
    p.add_argument("--analyse-only", action="store_true")
    p.add_argument("--quick", action="store_true", help="one pair, one seed, 100 steps")
    args = p.parse_args(argv)
    if args.quick:
        args.specimens, args.records, args.seeds = "bwbn", "2", "1"
        args.steps, args.pretrain_iterations, args.workers, args.no_paper = 40, 30, 1, True
        if args.out is None:
            args.out = Path(tempfile.mkdtemp(prefix="ann-equivalence-")) / "runs.jsonl"
    if args.out is None:
        p.error("--out is required (the JSONL file of run rows)")
    args.specimens = args.specimens.split(",")
    args.records = [int(r) for r in args.records.split(",")]
    args.seeds = [int(s) for s in args.seeds.split(",")]
    info: dict[str, Any] = {"machine_start": machine(), "commit": _commit(),
                            "argv": argv if argv is not None else sys.argv[1:],
                            "start_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    if args.analyse_only:
        _report(args, info)
        return
    print("machine:", info["machine_start"], "commit", info["commit"], flush=True)
    done = {run_key(r) for r in load(args.out, args.steps)}
    todo = [k for k in planned(args.specimens, args.records, args.seeds, not args.no_paper)
            if k not in done]
    print(f"{len(done)} runs already in {args.out}, {len(todo)} to do", flush=True)
    if todo:
        layouts = tuple(sorted({k[0] for k in todo}))
        t0 = time.perf_counter()
        models, pairs = prepare(args.specimens, args.records, args.steps,
                                args.pretrain_iterations, layouts)
        print(f"prepared {len(pairs)} pairs in {time.perf_counter() - t0:.1f} s", flush=True)
        by_key = {(p.layout, p.label): p for p in pairs}
        tasks: list[Task] = [(k, models[_specimen(k[1])], by_key[(k[0], k[1])]) for k in todo]
        args.out.parent.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        with args.out.open("a") as fh:
            count = 0

            def keep(_index: int, result: dict[str, Any]) -> None:
                nonlocal count
                count += 1
                row = {**result, "steps": args.steps}
                fh.write(json.dumps(row) + "\n")
                fh.flush()
                el = time.perf_counter() - t0
                print(f"[{count}/{len(todo)} {el / 60:5.1f} min] {row['layout']:<14} "
                      f"{row['pair']:<26} {row['method']:<16} seed {row['seed']}: MAETH "
                      f"{row['maeth']:8.3f} kN, teacher-forced RMSE "
                      f"{row['teacher_forced_rmse']:.4f} kN, LM it {row['iterations_mean']:.1f}, "
                      f"cpu median {row['cpu_ms_median']:.1f} p99 {row['cpu_ms_p99']:.1f} ms, "
                      f"{row['run_s']:.1f} s", flush=True)

            run_sweep(one_run, tasks, workers=args.workers, on_result=keep)
    info["machine_end"] = machine()
    info["end_utc"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    _report(args, info)


if __name__ == "__main__":
    main()
