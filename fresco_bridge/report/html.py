"""``fresco-bridge report RUN_DIR``: one self-contained HTML file per run (PNGs inlined).

Sections (element ids): ``overview`` (what a test engineer reads first: what was tested, the
headline figures, the diagnosis in words, what to do next; ``report.overview``), ``summary``
(numbers per site, session and actuator), ``site-<name>`` (hysteresis, command vs measured,
error monitors, synchronization subspace; an updatable site, without an actuator, its
hysteresis only), ``updating-<name>`` for an updatable site (its twin hysteresis, predicted vs
source force, the source's one-step error, learning lag and update time, from its update
lines), ``correction-<name>`` for a site with displacement correction (corrections per trial,
residual per step with the tolerance: ``report.correction``), ``diagnosis-<site>`` when the
run directory holds a site's diagnosis (``report.diagnosis``: verdict, magnitude, shrink,
overlay), ``events``, ``run`` (metadata and notes) and ``config`` (the snapshot). The same
summary numbers (and the overview's, and the corrections') are embedded as JSON in
``<script id="summary-data" type="application/json">`` so that a curation pipeline can read
them without scraping the tables.
"""

from __future__ import annotations

import base64
import html
import json
import math
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..indicators import IndicatorError, tracking_indicator
from ..numbers import fmt
from ..runs import (
    Run,
    SessionSignals,
    SiteSummary,
    human_size,
    load_run,
    session_signals,
    summarise,
)
from . import figures
from .correction import correction_data, correction_section
from .diagnosis import diagnosis_sections
from .overview import overview_section

REPORT_FILE = "report.html"
MAX_EVENT_ROWS = 2000

_CSS = """
body{font-family:system-ui,sans-serif;margin:2em auto;max-width:72em;color:#222;padding:0 1em}
h1{font-size:1.5em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:2em}
table{border-collapse:collapse;font-size:.9em;margin:.5em 0}
td,th{border:1px solid #ddd;padding:.25em .5em;text-align:left;vertical-align:top}
th{background:#f4f4f4}td.n{text-align:right;font-variant-numeric:tabular-nums}
pre{background:#f7f7f7;padding:1em;overflow:auto;font-size:.85em}
img{max-width:100%;display:block;margin:.5em 0}.note{background:#fff4d6;padding:.5em 1em}
figure{margin:1em 0}figcaption{color:#555;font-size:.9em}.wide{overflow-x:auto}
table.overview{font-size:1em;width:100%}table.overview th{width:12em}
.fig{font-weight:600;font-variant-numeric:tabular-nums}
caption{text-align:left;font-weight:600;padding:.3em 0}
"""

# (key, header, unit) of the summary's two per-session tables (a page wide each); keys are
# SessionSummary fields.
_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("session", "session", ""), ("actuator", "actuator", ""), ("steps", "steps", ""),
    ("time_end", "end time", "s"), ("peak_cmd", "peak |command|", "mm"),
    ("peak_meas", "peak |measured|", "mm"), ("force_min", "min force", "kN"),
    ("force_max", "max force", "kN"),
)
_TRACKING_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("session", "session", ""), ("actuator", "actuator", ""),
    ("max_tracking_error", "max |error|", "mm"),
    ("peak_amplitude_error", "peak amplitude error", "mm"), ("nrms", "NRMS", ""),
    ("ti_final", "final TI", "mm²"), ("fei_amplitude", "FEI amplitude", ""),
    ("fei_delay", "FEI delay", "s"), ("xcorr_delay", "xcorr delay", "s"),
)


def _e(v: object) -> str:
    return html.escape(str(v), quote=True)


def _img(png: bytes, alt: str, caption: str) -> str:
    data = base64.b64encode(png).decode("ascii")
    return (f'<figure><img alt="{_e(alt)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{_e(caption)}</figcaption></figure>")


def _json_safe(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _meta_value(value: Any) -> str:
    """A run.json value as a person reads it: ``disp mm, force kN, time s``, ``damper, twin``."""
    if isinstance(value, dict):
        return ", ".join(f"{k} {_meta_value(v)}" for k, v in value.items())
    if isinstance(value, list):
        return ", ".join(_meta_value(v) for v in value)
    return str(value)


def _meta_section(run: Run) -> str:
    rows = [("run directory", str(run.directory)), ("size", human_size(run.size_bytes))]
    for key, value in run.meta.items():
        rows.append((key, _meta_value(value)))
    body = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in rows)
    notes = "".join(f'<p class="note">{_e(n)}</p>' for n in run.notes)
    return f'<section id="run"><h2>Run</h2><table>{body}</table>{notes}</section>'


_TRACKING_KEYS = frozenset({"max_tracking_error", "peak_amplitude_error", "nrms", "ti_final",
                            "fei_amplitude", "fei_delay", "xcorr_delay"})
"""Columns about an actuator's tracking: "–" for an updatable site, which has none."""


def _summary_section(summaries: list[SiteSummary], twins: frozenset[str] = frozenset()) -> str:
    parts = ['<section id="summary"><h2>Summary</h2>']
    site_rows = "".join(
        f'<tr data-site="{_e(s.site)}"><td>{_e(s.site)}</td>'
        f'<td class="n" data-key="steps">{s.steps}</td>'
        f'<td class="n" data-key="sessions">{s.sessions}</td>'
        f'<td class="n" data-key="holds">{s.holds}</td>'
        f'<td class="n" data-key="limit_events">{s.limit_events}</td>'
        f"<td>{_e(', '.join(f'{k} {n}' for k, n in sorted(s.events.items())) or 'none')}</td>"
        "</tr>"
        for s in summaries
    )
    parts.append("<table><tr><th>site</th><th>committed steps</th><th>sessions</th>"
                 f"<th>holds</th><th>limit events</th><th>events</th></tr>{site_rows}</table>")
    tables = [_session_table(summaries, twins, columns, caption)
              for columns, caption in ((_COLUMNS, "Each session"),
                                       (_TRACKING_COLUMNS, "Tracking of each session"))]
    if any(s.sessions_detail for s in summaries):
        parts.extend(tables)
        parts.append("<p>Errors are measured − command of each actuator; NRMS, TI, FEI and the "
                     "cross-correlation delay follow <code>fresco_bridge/indicators.py</code> "
                     "(positive delay: the measurement lags). TI decreasing means lag "
                     "(energy added)."
                     + (" An updatable site has no actuator: –." if twins else "") + "</p>")
    else:
        parts.append('<p class="note">No committed steps in this run.</p>')
    parts.append("</section>")
    return "".join(parts)


def _session_table(summaries: list[SiteSummary], twins: frozenset[str],
                   columns: tuple[tuple[str, str, str], ...], caption: str) -> str:
    head = "".join(f"<th>{_e(h)}{f' ({_e(u)})' if u else ''}</th>" for _, h, u in columns)
    rows = []
    for s in summaries:
        na = s.site in twins
        for d in s.sessions_detail:
            cells = "".join(
                f'<td class="n" data-key="{k}">'
                f'{"–" if na and k in _TRACKING_KEYS else _e(fmt(getattr(d, k), digits=6))}</td>'
                for k, _, _ in columns)
            rows.append(f'<tr data-site="{_e(s.site)}"><td>{_e(s.site)}</td>{cells}</tr>')
    return (f"<table><caption>{_e(caption)}</caption><tr><th>site</th>{head}</tr>"
            f"{''.join(rows)}</table>")


def _twin_site_section(run: Run, site: str, source: str) -> str:
    """An updatable site has no actuator: its "measurement" is its trial, so tracking error,
    TI, FEI and synchronization would be flat zeros. Its served hysteresis and its learning
    are in ``updating-<site>``."""
    signals = [s for s in session_signals(run.steps) if s.site == site]
    return "".join([
        f'<section id="site-{_e(site)}"><h2>Site {_e(site)} (updatable)</h2>',
        f'<p>The twin of <a href="#site-{_e(source)}">{_e(source)}</a>: no actuator, the '
        "force it answered is its updater's prediction at the trial displacement, so there "
        "is no tracking error to show. How it learned: "
        f'<a href="#updating-{_e(site)}">Updating: {_e(site)}</a>.</p>',
        _img(figures.hysteresis(site, signals, served=True), f"{site} hysteresis",
             "The force the twin served (its updater's prediction) against its trial "
             "displacement."),
        "</section>",
    ])


def _site_section(run: Run, site: str, warn: float | None) -> str:
    twin_of = run.sources().get(site)
    if twin_of is not None:
        return _twin_site_section(run, site, twin_of)
    signals = [s for s in session_signals(run.steps) if s.site == site]
    ti = []
    for sig in signals:
        try:
            ti.append(tracking_indicator(sig.cmd[:, 0], sig.meas[:, 0]))
        except IndicatorError:  # non-finite samples: no TI line for this session
            ti.append(np.full(sig.step.size, math.nan))
    monitors = [m for m in run.monitors if m.site == site]
    n = sum(s.step.size for s in signals)
    markers = _event_times(run, site, signals)
    thin = "" if n <= figures.MAX_POINTS else (
        f" Lines are drawn from every {math.ceil(n / figures.MAX_POINTS)}th step.")
    return "".join([
        f'<section id="site-{_e(site)}"><h2>Site {_e(site)}</h2>',
        _img(figures.hysteresis(site, signals), f"{site} hysteresis",
             "Measured force against measured displacement (actuator space)." + thin),
        _img(figures.command_vs_measured(site, signals, markers), f"{site} command vs measured",
             "Command (ctrl) and measured (daq) displacement of each committed step; dotted "
             "lines mark holds, limit hits and monitor warnings." + thin),
        _img(figures.error_monitors(site, signals, ti, monitors, warn),
             f"{site} error monitors",
             "Top: tracking error. Middle: tracking indicator computed from the committed steps "
             "(actuator 1) and, dashed, the online monitor recorded during the run (it runs "
             "across sessions). Bottom: the online monitor's FEI amplitude and delay over its "
             "sliding window." + thin),
        _img(figures.synchronization(site, signals), f"{site} synchronization subspace",
             "Measured against command displacement; the dashed line is perfect tracking."),
        "</section>",
    ])


def _updating_section(run: Run, twin: str, source: str) -> str:
    """An updatable site's learning: its committed steps (trial d, predicted F), its source's,
    and its update lines (format 5; a record without them still shows the forces)."""
    mine = [s for s in run.steps if s.site == twin]
    theirs = [s for s in run.steps if s.site == source]
    ups = [u for u in run.updates if u.get("site") == twin]
    steps = np.array([int(u["step"]) for u in ups], dtype=float)
    through = np.array([int(u["through"]) for u in ups], dtype=float)
    seconds = np.array([float(u["secs"]) for u in ups])
    error = np.array([float(u.get("err", math.nan)) for u in ups])
    png = figures.updating(
        twin, source, np.array([s.cmd_disp[0] for s in mine]),
        np.array([s.meas_force[0] for s in mine]), np.array([s.time for s in mine]),
        np.array([s.time for s in theirs]), np.array([s.meas_force[0] for s in theirs]),
        steps, steps - through, 1e3 * seconds, error)
    learned = seconds[seconds > 0]
    rows = [("source", source), ("committed twin steps", str(len(mine))),
            ("update lines", str(len(ups))),
            ("source step learned through (last)", str(int(through[-1])) if ups else "none"),
            ("median / max update time (ms)",
             f"{fmt(1e3 * float(np.median(learned)), digits=4)} / "
             f"{fmt(1e3 * float(learned.max()), digits=4)}" if learned.size else "none"),
            ("median / max source one-step error (kN)",
             f"{fmt(float(np.nanmedian(error)), digits=4)} / "
             f"{fmt(float(np.nanmax(error)), digits=4)}" if np.isfinite(error).any()
             else "not predicted by this updater")]
    table = "".join(f'<tr><th>{_e(k)}</th><td class="n">{_e(v)}</td></tr>' for k, v in rows)
    note = "" if ups else ('<p class="note">The record has no update lines for this site (a '
                           "record written before format 5).</p>")
    return "".join([
        f'<section id="updating-{_e(twin)}"><h2>Updating: {_e(twin)} learns from '
        f"{_e(source)}</h2><table>{table}</table>{note}",
        _img(png, f"{twin} updating",
             "Top left: the twin's trial displacement against the force it answered. Top "
             "right: that force and the source's measured force in time. Middle left: the "
             "source's one-step error, the measured force of the last source step learned for "
             "each twin step against the updater's prediction of it from the source's "
             "measured past before learning it (only updaters that predict it: "
             "online_improved). Middle right: how many source steps each twin step's answer "
             "had not learned yet (1 with previous-step causality, 0 with same-step). Bottom: "
             "the worker's update time for each twin step (0: nothing new learned) and its "
             "distribution over the steps that learned."),
        "</section>",
    ])


def _event_times(run: Run, site: str, signals: list[SessionSignals]) -> list[tuple[float, str]]:
    """(time, kind) of the site's holds, limit hits and monitor warnings: the time of the
    last step committed before the event (its ``step``) in the same session."""
    times = {(sig.session, int(s)): float(t)
             for sig in signals for s, t in zip(sig.step, sig.time, strict=True)}
    out = []
    for ev in run.events:
        kind = str(ev.get("event", ""))
        if ev.get("site") != site or kind not in figures.MARKER_COLORS:
            continue
        step = ev.get("step")
        t = times.get((int(ev.get("session", 0)), int(step))) if isinstance(step, int) else None
        if t is not None:
            out.append((t, kind))
    return out


def _events_section(run: Run) -> str:
    shown = run.events[:MAX_EVENT_ROWS]
    rows = []
    for ev in shown:
        extra = {k: v for k, v in ev.items()
                 if k not in ("seq", "t", "kind", "site", "session", "event", "reason", "step")}
        rows.append(
            f'<tr data-event="{_e(ev.get("event", ""))}"><td class="n">{_e(ev.get("seq", ""))}'
            f'</td><td class="n">{_e(fmt(ev.get("t"), digits=6))}</td>'
            f'<td>{_e(ev.get("site", ""))}</td><td class="n">{_e(ev.get("session", ""))}</td>'
            f'<td class="n">{_e(ev.get("step", ""))}</td><td>{_e(ev.get("event", ""))}</td>'
            f'<td>{_e(ev.get("reason", ""))}</td>'
            f"<td>{_e(json.dumps(extra)) if extra else ''}</td></tr>"
        )
    more = (f'<p class="note">{len(run.events) - len(shown)} more event(s) not shown; '
            "see record.jsonl.</p>" if len(run.events) > len(shown) else "")
    table = ("<table><tr><th>seq</th><th>t (s)</th><th>site</th><th>session</th><th>step</th>"
             f"<th>event</th><th>reason</th><th>details</th></tr>{''.join(rows)}</table>"
             if rows else "<p>No events.</p>")
    return (f'<section id="events"><h2>Events ({len(run.events)})</h2><p>Holds, limit hits, '
            "faults, monitor warnings and integrator sessions; t is seconds since the bridge "
            f"started.</p>{table}{more}</section>")


def _config_section(run: Run) -> str:
    body = (f"<pre>{_e(run.config_text)}</pre>" if run.config_text is not None
            else '<p class="note">No configuration snapshot (config.toml missing).</p>')
    return f'<section id="config"><h2>Configuration snapshot</h2>{body}</section>'


def render_report(run: Run) -> str:
    """The whole report as one HTML string."""
    summaries = summarise(run)
    warn = run.config_value("telemetry", "warn_tracking_error", None)
    data = {
        "run": run.name,
        "sites": {s.site: {"steps": s.steps, "sessions": s.sessions, "holds": s.holds,
                           "limit_events": s.limit_events, "events": s.events,
                           "detail": [{k: _json_safe(v) for k, v in d.as_dict().items()}
                                      for d in s.sessions_detail]}
                  for s in summaries},
    }
    corrected = correction_data(run)
    data["correction"] = corrected
    overview, data["overview"] = overview_section(run, summaries, corrected)
    generated = datetime.now(UTC).isoformat(timespec="seconds")
    started = run.meta.get("started_utc", "?")
    return "".join([
        '<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">',
        f"<title>fresco-bridge run {_e(run.name)}</title><style>{_CSS}</style></head><body>",
        f"<h1>Hybrid simulation run {_e(run.name)}</h1>",
        f"<p>Started {_e(started)} (UTC); sites: {_e(', '.join(run.sites) or 'none')}. "
        f"Report generated {_e(generated)} by fresco-bridge {_e(__version__)}. "
        "Units: mm, kN, s.</p>",
        overview,
        _summary_section(summaries, frozenset(run.sources())),
        *(_site_section(run, site, float(warn) if warn is not None else None)
          for site in run.sites),
        *(correction_section(run, site, d, _img) for site, d in corrected.items()),
        *(_updating_section(run, twin, source) for twin, source in run.sources().items()),
        *diagnosis_sections(run.directory, _img),
        _events_section(run),
        _meta_section(run),
        _config_section(run),
        '<script type="application/json" id="summary-data">',
        json.dumps(data).replace("</", "<\\/"),
        "</script></body></html>\n",
    ])


def write_report(run_dir: Path, out: Path | None = None) -> Path:
    """Write the report of ``run_dir`` to ``out`` (a file, or a directory to put report.html
    in; default ``RUN_DIR/report.html``); returns its path."""
    run = load_run(run_dir)
    path = out if out is not None else run_dir / REPORT_FILE
    if path.is_dir():
        path = path / REPORT_FILE
    text = render_report(run)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)
    return path
