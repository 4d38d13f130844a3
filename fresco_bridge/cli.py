"""``fresco-bridge``: every command's parser, and serve, check, demo. What a command raises
becomes an exit code in ``exit_codes.py`` (as for the light entry, ``entry.py``)."""

from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import sys
from pathlib import Path

from . import _compiled
from .config import ConfigError, load_config
from .config_model import REDACTED
from .ctl import ControlError, add_ctl_parser, ctl_command
from .diagnosis.cli import COMMANDS as DIAGNOSIS_COMMANDS
from .diagnosis.cli import add_diagnosis_parsers, diagnosis_command
from .exit_codes import Interrupted, exit_code, reader_gone
from .lab import LabError, add_lab_parser, lab_command
from .logs import configure as configure_logging
from .progress import command_name
from .report.cli import COMMANDS as REPORT_COMMANDS
from .report.cli import add_report_parsers, report_command
from .runs import RunDirError, check_resumable, mark_interrupted, resolve_run
from .study import add_study_parser, study_command
from .updating.cli import add_updater_parser, updater_command


async def _serve(config_path: Path | None, resume: Path | None = None) -> int:
    from .daemon import Bridge

    if config_path is None:  # resume with the run's own snapshot
        assert resume is not None
        config_path = resume / "config.toml"
        if REDACTED in config_path.read_text(encoding="utf-8"):
            raise ConfigError(f"{config_path}: the snapshot's secrets were redacted; pass "
                              "--config with the file the run was started with")
    cfg, text = load_config(config_path)
    bridge = Bridge(cfg, text, resume=resume)
    stop = asyncio.Event()
    caught: list[signal.Signals] = []
    loop = asyncio.get_running_loop()

    def on_signal(sig: signal.Signals) -> None:
        caught.append(sig)
        stop.set()

    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, on_signal, sig)
    await bridge.start()
    serving: list[str] = []
    try:
        ports = ", ".join(f"{n}={p}" for n, p in bridge.ports.items())
        try:
            print(f"fresco-bridge ready: {ports}", flush=True)
        except BrokenPipeError:  # whoever read stdout left: the lab's test goes on
            reader_gone()
            logging.getLogger("fresco_bridge").warning(
                "stdout's reader went away before the ready line (%s); serving on", ports)
        await stop.wait()
        serving = [name for name, site in bridge.sites.items() if site.busy]
    finally:
        await bridge.close()
    record = bridge.record
    if serving and caught:  # stopped mid-test: the run was interrupted, not finished
        raise _interrupted_serve(caught[0], serving, config_path,
                                 None if record is None else record.directory)
    if record is not None:  # between tests: say where the run went and what to do with it
        run, cmd = record.directory, command_name()
        logging.getLogger("fresco_bridge").info(
            "stopped; run record %s (next: %s runs show %s)", run, cmd, run)
    return 0


def _interrupted_serve(sig: signal.Signals, serving: list[str], config: Path,
                       run: Path | None) -> Interrupted:
    """The one line of a bridge stopped while its sites served clients: the run is recorded
    as interrupted (resumable), the exit code 128 + the signal."""
    how = "Ctrl-C" if sig == signal.SIGINT else sig.name
    what = (f"fresco-bridge serve stopped by {how} while site(s) {', '.join(serving)} served a "
            "client")
    if run is None:
        return Interrupted(f"{what} (recording is off: nothing was recorded)", 128 + sig)
    mark_interrupted(run)
    cmd = command_name()
    return Interrupted(f"{what}; the run is recorded as interrupted: {run} (next: {cmd} runs "
                       f"show {run}; to continue it: {cmd} serve --config {config} --resume "
                       f"{run})", 128 + sig)


def _warn_if_stale() -> None:
    """Loudly, at every start: a compiled module whose source changed runs the old code."""
    stale = _compiled.stale()
    if stale:
        print(f"fresco-bridge: WARNING: {_compiled.stale_message(stale)}", file=sys.stderr)


def _serve_on_its_loop(config_path: Path | None, resume: Path | None) -> int:
    """``serve`` on the event loop its config names (``[bridge] event_loop``)."""
    from .loops import run

    path = config_path if config_path is not None else (resume or Path()) / "config.toml"
    try:
        kind = load_config(path)[0].bridge.event_loop
    except (ConfigError, OSError):
        kind = "asyncio"  # _serve reports what is wrong with the config
    return run(_serve(config_path, resume), kind)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="fresco-bridge",
        description="OpenFresco-compatible lab daemon for hybrid simulation: serve experimental "
                    "sites to OpenSees genericClient / ShadowExpSite clients, run the demo, "
                    "report on recorded runs, operate a running bridge.",
        epilog="Units: mm, kN, s. Configuration: see examples/lab.toml and docs/configuration.md.")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True)
    p_serve = sub.add_parser("serve", help="run the bridge daemon from a lab config")
    p_serve.add_argument("--config", type=Path, required=True, help="lab TOML file")
    p_serve.add_argument("--resume", metavar="RUN", default=None,
                         help="continue an interrupted run (a run directory, or a name under "
                              "the config's run_dir) instead of starting a new one")
    p_check = sub.add_parser("check", help="validate a lab config and exit")
    p_check.add_argument("--config", type=Path, required=True)
    demo_help = ("the source paper's story end to end: the two-story frame, the tested "
                 "damper on the simulated rig, its twin learned online, the diagnosis")
    p_demo = sub.add_parser(
        "demo", help=demo_help,
        description=f"Run {demo_help}, in one process on embedded defaults (no broker, no "
                    "hardware, no file from outside the package). Four acts: 1 the "
                    "characterisation test, 2 the hybrid test through the bridge, 3 the twin's "
                    "scores against the calibrated Bilinear, 4 the diagnosis; then the report. "
                    "Each act's bridge logs into its run directory's bridge.log.",
        epilog="Ctrl-C stops it with one line; the run is then recorded as interrupted.")
    p_demo.add_argument("--simple", action="store_true",
                        help="the plumbing alone: an ideal bilinear damper, no rig, no twin")
    p_demo.add_argument("--no-progress", action="store_true", help="no progress bars")
    p_demo.add_argument("--record", type=Path, default=None,
                        help="PEER .AT2 ground motion (default: seeded Kanai-Tajimi record)")
    p_demo.add_argument("--pga", type=float, default=3.0, help="PGA in m/s² (default 3.0)")
    p_demo.add_argument("--duration", type=float, default=20.0, help="seconds of synthetic record")
    p_demo.add_argument("--seed", type=int, default=1, help="synthetic record seed")
    p_demo.add_argument("--runs", type=Path, default=Path("runs"), help="run directory root")
    p_demo.add_argument("--transport", choices=("tcp", "udp"), default="tcp",
                        help="how the integrator reaches the bridge's sites, as genericClient's "
                             "default or its -udp (default: tcp)")
    p_demo.add_argument("--mqtt", metavar="HOST[:PORT]", default=None,
                        help="publish live telemetry to this MQTT broker (default: off)")
    p_demo.add_argument("--mqtt-prefix", default="fresco", help="MQTT topic prefix")
    p_demo.add_argument("--metrics-port", type=int, default=None,
                        help="serve Prometheus /metrics on 127.0.0.1:PORT (0 = any free port)")
    add_report_parsers(sub)  # report, runs list|show|export, export (alias)
    add_lab_parser(sub)
    add_ctl_parser(sub)
    add_study_parser(sub)
    add_updater_parser(sub)
    add_diagnosis_parsers(sub)  # diagnose, diagnose-bench
    args = parser.parse_args(argv)
    configure_logging(args.verbose)
    _warn_if_stale()
    return exit_code(lambda: _run(args), (ConfigError, LabError, RunDirError, ControlError))


def _diagnose_into_run(run: str, runs: Path, sites: list[str]) -> None:
    """``report RUN --diagnose SITE``: each site's diagnosis into ``RUN/diagnosis-SITE``."""
    from .diagnosis.load import DiagnosisInputError
    from .diagnosis.rundir import diagnose_into_run
    from .progress import ProgressBar
    from .runs import load_run

    run_dir = resolve_run(run, runs)
    known = load_run(run_dir).sites
    for site in sites:
        if site not in known:
            raise RunDirError(f"{run_dir}: --diagnose {site}: no such site in this run "
                              f"(sites: {', '.join(known) or 'none'})")
        try:
            h = diagnose_into_run(run_dir, site, ProgressBar(f"diagnose {site}", 1))
        except DiagnosisInputError as exc:
            raise RunDirError(f"{run_dir}: --diagnose {site}: {exc}") from None
        print(f"{run_dir}/diagnosis-{site}: {h['effect']}")


def _run(args: argparse.Namespace) -> int:
    """The command ``args`` names; its exit code (errors: ``exit_code``)."""
    if args.command == "serve":
        resume = None
        if args.resume is not None:
            cfg, _ = load_config(args.config)
            resume = check_resumable(resolve_run(args.resume, cfg.bridge.run_dir))
        return _serve_on_its_loop(args.config, resume)
    if args.command == "runs" and args.runs_command == "resume":
        run = check_resumable(resolve_run(args.run, args.runs))
        return _serve_on_its_loop(args.config, run)
    if args.command == "check":
        from .site_kinds import SITE_KINDS

        cfg, _ = load_config(args.config)
        print(f"{args.config}: OK ({len(cfg.sites)} site(s): "
              + ", ".join(f"{s.name} {s.transport}:{s.port}" + SITE_KINDS[s.kind].describe(s)
                          for s in cfg.sites) + ")")
        return 0
    if args.command == "demo":
        from .demo import run_demo, story_terminal
        from .demo_story import run_story

        common = {"record": args.record, "pga": args.pga, "duration": args.duration,
                  "seed": args.seed, "runs": args.runs, "transport": args.transport,
                  "mqtt": args.mqtt, "mqtt_prefix": args.mqtt_prefix,
                  "metrics_port": args.metrics_port}
        with story_terminal():
            if args.simple:
                run_demo(**common)
            else:
                run_story(**common, progress=not args.no_progress)
        return 0
    if args.command == "lab":
        return lab_command(args)
    if args.command == "ctl":
        return ctl_command(args)
    if args.command == "study":
        return study_command(args)
    if args.command == "updater":
        return updater_command(args)
    if args.command == "report" and args.diagnose:
        _diagnose_into_run(args.run, args.runs, args.diagnose)
    if args.command in REPORT_COMMANDS:
        return report_command(args)
    if args.command in DIAGNOSIS_COMMANDS:
        return diagnosis_command(args)
    return 0

if __name__ == "__main__":
    sys.exit(main())
