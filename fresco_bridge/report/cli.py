"""The ``report``, ``runs list|show|export`` and ``export`` sub-commands (parsers and actions).

``export RUN_DIR`` is an alias of ``runs export RUN_DIR``: one code path for both. Errors are
raised (``RunDirError``) for ``fresco_bridge.cli`` to turn into an exit code.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..record.export import write_corrections_csv, write_csv
from ..runs import (
    RunDirError,
    format_listing,
    format_show,
    list_runs,
    load_run,
    resolve_run,
    summarise,
)

COMMANDS = frozenset({"report", "runs", "export"})
HDF5_SUFFIXES = (".h5", ".hdf5")


def add_report_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``report``, ``runs`` and ``export`` to the top-level sub-parsers."""
    runs_root = argparse.ArgumentParser(add_help=False)
    runs_root.add_argument("--runs", type=Path, default=Path("runs"),
                           help="directory holding the run directories (default: runs)")
    p_rep = sub.add_parser("report", parents=[runs_root],
                           help="write a self-contained HTML report of a recorded run")
    p_rep.add_argument("run", help="run directory (or a run name/prefix under --runs)")
    p_rep.add_argument("-o", "--output", type=Path, default=None,
                       help="output file (default: RUN_DIR/report.html)")
    p_rep.add_argument("--diagnose", metavar="SITE", action="append", default=[],
                       help="diagnose SITE first (as `diagnose RUN --site SITE --report "
                            "RUN/diagnosis-SITE`) for the report's diagnosis section; "
                            "repeatable (without it, a diagnosis already in the run "
                            "directory is shown). Run by fresco_bridge.cli: the diagnosis "
                            "draws with this package's figures")

    p_runs = sub.add_parser("runs", help="list, show and export recorded runs")
    rs = p_runs.add_subparsers(dest="runs_command", required=True)
    rs.add_parser("list", parents=[runs_root], help="one line per run directory")
    p_show = rs.add_parser("show", parents=[runs_root], help="metadata and per-site summary")
    p_show.add_argument("run", help="run directory (or a run name/prefix under --runs)")
    p_res = rs.add_parser("resume", parents=[runs_root],
                          help="continue an interrupted run (bridge killed, host lost): serve "
                               "again, appending to its record from the last committed step")
    p_res.add_argument("run", help="run directory (or a run name/prefix under --runs)")
    p_res.add_argument("--config", type=Path, default=None,
                       help="lab TOML the run was started with (default: the run's snapshot, "
                            "unless its secrets were redacted)")
    for p_exp in (rs.add_parser("export", parents=[runs_root],
                                help="committed steps to CSV, or the whole run to HDF5"),
                  sub.add_parser("export", parents=[runs_root],
                                 help="alias of 'runs export'")):
        p_exp.add_argument("run", help="run directory (or a run name/prefix under --runs)")
        p_exp.add_argument("-o", "--output", type=Path, default=None,
                           help="output file (default: RUN_DIR/steps.csv or RUN_DIR/run.h5)")
        p_exp.add_argument("--format", choices=("csv", "hdf5"), default=None,
                           help="default: hdf5 for a .h5/.hdf5 output, else csv")
        p_exp.add_argument("--site", default=None, help="only this site")
        p_exp.add_argument("--corrections", action="store_true",
                           help="the displacement corrections instead of the committed steps: "
                                "one CSV row per command of each corrected trial (default "
                                "output: RUN_DIR/corrections.csv)")


def _export(args: argparse.Namespace) -> int:
    run = load_run(resolve_run(args.run, args.runs))
    for note in run.notes:
        print(f"note: {run.directory}: {note}", file=sys.stderr)
    fmt = args.format or (
        "hdf5" if args.output is not None and args.output.suffix in HDF5_SUFFIXES else "csv")
    if args.site is not None and args.site not in run.sites:
        raise RunDirError(f"{run.directory}: no site {args.site!r} in this run (sites: "
                          f"{', '.join(run.sites) or 'none'})")
    if args.corrections:
        if fmt != "csv":
            raise RunDirError("--corrections writes CSV; leave out --format hdf5 (the HDF5 "
                              "export of the run holds them: /sites/<site>/correction)")
        out = args.output or run.directory / "corrections.csv"
        n = write_corrections_csv(run.corrections, out, site=args.site)
        print(f"wrote {out}: {n} command(s) of {len(run.corrections)} corrected trial(s)")
        return 0
    if fmt == "hdf5":
        from .hdf5 import export_hdf5

        out = args.output or run.directory / "run.h5"
        n = export_hdf5(run, out, site=args.site)
    else:
        out = args.output or run.directory / "steps.csv"
        from ..site_kinds import SITE_KINDS

        kinds = {site: (kind, kind in SITE_KINDS and SITE_KINDS[kind].predicted)
                 for site, kind in run.site_kinds().items()}
        n = write_csv(run.steps, out, site=args.site, kinds=kinds)
    print(f"wrote {out}: {n} committed step(s)")
    return 0


def report_command(args: argparse.Namespace) -> int:
    """Run the parsed ``report``/``runs``/``export`` command; returns the exit code."""
    if args.command == "report":
        from .html import write_report

        run_dir = resolve_run(args.run, args.runs)
        path = write_report(run_dir, args.output)
        print(f"wrote {path} (report of {run_dir})")
        return 0
    if args.command == "export" or args.runs_command == "export":
        return _export(args)
    if args.runs_command == "list":
        runs = list_runs(args.runs)
        print(format_listing(runs) if runs else f"{args.runs}: no runs")
        return 0
    run = load_run(resolve_run(args.run, args.runs))
    print(format_show(run, summarise(run)))
    return 0
