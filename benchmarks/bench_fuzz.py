"""Long fuzz run of a live bridge: >= 100 000 hostile inputs from a seeded generator.

Question: after hundreds of thousands of malformed and adversarial inputs, does the
bridge still serve a good client correctly, has no non-finite or out-of-limit command reached a
controller, are memory and file descriptors bounded, and does the record still parse?

Method: the same live bridge and actions as the CI state machine
(``tests/bridge/server/fuzz_driver.py``, ``test_fuzz_stateful.py``): a bridge in a thread with
sites ``good`` / ``fuzz`` (TCP) / ``fuzzu`` (UDP) behind absolute limits ±5 mm and an
increment limit; the actions are garbage bytes, absurd size IDs with arbitrary vectors,
well-formed sessions with hostile values (NaN, ±inf, 1e308, beyond the limits) and any action
codes that may vanish mid-step (RST), UDP datagrams, held connections dropped (FIN or RST),
operator commands (pause, resume, abort, status), and hostile lines on the control socket
(garbage bytes, nesting up to 4,000 levels, huge numbers, control characters in a site or an
id), each of which must get a one-line answer. Here a ``random.Random(seed)`` draws each
action's arguments (hypothesis draws them in CI). After every action the commands forwarded
since the last one are checked (finite, within ±5 mm); every ``--check-every`` actions the full
invariant (a good client served correctly, fds and RSS bounded after a settle deadline); every
``--record-every`` actions the whole record is parsed. A violated invariant is counted and the
run goes on; an internal error of the bridge (a ``log.exception`` of a session ended by a bug)
is counted as a crash, and so is a bridge thread that died. Every line the bridge logs goes
through the daemon's own formatter and filters (``logs.configure``'s): a line that is not one
line, holds a control character or a traceback is counted as a bad log line.

    .venv/bin/python -m benchmarks.bench_fuzz [--quick] --inputs 100000 --seed 2026

Feeds BENCHMARKS.md, "Fuzz and soak". ``--quick``: 5000 inputs, a smoke run. Exit status 1 when
a command escaped the limits, the bridge crashed or an invariant was violated.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import random
import re
import socket
import struct
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

from fresco_bridge import ctl
from fresco_bridge.logs import OneLineFormatter, OutsideLineFilter, RateLimitFilter
from fresco_bridge.record import read_record
from tests.bridge.server.fuzz_driver import LIMIT, FuzzTarget, valid_size_id

REQUEST_CODES = (3, 5, 6, 7, 10, 12, 13, 14, 15, 42, 98, 99)
KEEP_OPEN = 0.2
"""Share of garbage/frames connections left open (a held one blocks its site until the idle
deadline, 0.5 s here, so more would leave most sessions refused as busy)."""
SPECIAL = (float("nan"), float("inf"), float("-inf"), -1e308, 1e308, 1e3, -0.0, 5e-324)


class _Crashes(logging.Handler):
    """Counts every record logged with a traceback (the bridge's ``log.exception``)."""

    def __init__(self) -> None:
        super().__init__(logging.ERROR)
        self.records: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.exc_info is not None:
            self.records.append(record.getMessage())


CONTROL_CHARS = "\n\r\x1b\x00\x7f\x85\u2028\u202e\t"
_UNPRINTABLE = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069]")


class _LogLines(logging.Handler):
    """The daemon's log as ``configure`` writes it (formatter and filters): every line counted,
    a bad one (several lines, a control character, a traceback) kept as a sample."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.setFormatter(OneLineFormatter("%(asctime)s %(levelname)-7s %(name)s: %(message)s"))
        self.addFilter(OutsideLineFilter())
        self.addFilter(RateLimitFilter())
        self.lines = 0
        self.bad: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        text = self.format(record)
        self.lines += 1
        if "\n" in text or _UNPRINTABLE.search(text) or "Traceback" in text:
            self.bad.append(text[:300])


def _hostile_text(rng: random.Random, most: int) -> str:
    return "".join(rng.choice(CONTROL_CHARS) if rng.random() < 0.3 else chr(rng.randint(32, 0x2fff))
                   for _ in range(rng.randint(0, most)))


def control_line(t: FuzzTarget, rng: random.Random) -> bool:
    """One hostile line on the control socket; True if it was answered with one JSON line
    (a line over the 4 KiB cap may be answered or cut: True either way)."""
    which = rng.randrange(4)
    if which == 0:
        line = _bytes(rng, 600).replace(b"\n", b" ")
    elif which == 1:
        line = rng.choice([b"[", b"{", b'{"a":', b'[{"command":']) * rng.randint(1, 4000)
    elif which == 2:
        line = json.dumps({"command": rng.choice(["status", "pause", "resume", "abort"]),
                           "site": _hostile_text(rng, 40), "id": _hostile_text(rng, 40)}).encode()
    else:
        line = b'{"command": "status", "id": ' + b"9" * rng.randint(1, 4080) + b"}"
    t.inputs += 1
    path = ctl.find_socket(None, t.run_dir, t.run_dir)
    answer = b""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(10.0)
        try:
            s.connect(str(path))
            s.sendall(line + b"\n")
            while not answer.endswith(b"\n"):
                chunk = s.recv(65536)
                if not chunk:
                    break
                answer += chunk
        except ConnectionError:
            return len(line) >= ctl.MAX_LINE
    if len(line) >= ctl.MAX_LINE and not answer:
        return True
    try:
        return answer.count(b"\n") == 1 and isinstance(json.loads(answer), dict)
    except ValueError:
        return False


def _any_float(rng: random.Random) -> float:
    """Any IEEE double, NaN payloads and subnormals included, or a special value."""
    if rng.random() < 0.3:
        return rng.choice(SPECIAL)
    value: float = struct.unpack("<d", rng.getrandbits(64).to_bytes(8, "little"))[0]
    return value


def _hostile_disp(rng: random.Random) -> float:
    r = rng.random()
    if r < 0.6:
        return rng.uniform(-LIMIT, LIMIT)
    if r < 0.85:
        return rng.choice(SPECIAL)
    return _any_float(rng)


def _bytes(rng: random.Random, most: int) -> bytes:
    return rng.randbytes(rng.randint(0, most))


def action(t: FuzzTarget, rng: random.Random) -> str:
    """One fuzz action with arguments drawn as the CI state machine's rules draw them."""
    kind = rng.choices(["garbage", "frames", "session", "udp", "drop", "operator", "control"],
                       weights=[3, 3, 6, 3, 2, 1, 1])[0]
    if kind == "garbage":
        t.garbage(_bytes(rng, 600), rng.random() < KEEP_OPEN)
    elif kind == "frames":
        which = rng.randrange(3)
        if which == 0:
            sid = tuple(rng.randint(-(2**31), 2**31 - 1) for _ in range(11))
        elif which == 1:
            sid = tuple(rng.randint(-2, 70) for _ in range(11))
        else:
            sid = valid_size_id(rng.randint(1, 64))
        vectors = [tuple(_any_float(rng) for _ in range(5)) for _ in range(rng.randint(0, 4))]
        t.frames(sid, vectors, rng.random() < KEEP_OPEN)
    elif kind == "session":
        n = rng.randint(1, 5)
        t.session([_hostile_disp(rng) for _ in range(n)],
                  [rng.choice(REQUEST_CODES) for _ in range(rng.randint(1, 5))],
                  rng.random() < 0.5, rng.random() < 0.5)
    elif kind == "udp":
        t.udp([b"a" if rng.random() < 0.3 else _bytes(rng, 200)
               for _ in range(rng.randint(0, 5))])
    elif kind == "drop":
        t.drop(rng.randint(0, 7), rng.random() < 0.5)
    elif kind == "control":
        if not control_line(t, rng):
            return "control-unanswered"
    else:
        # resume more often than pause/abort, so the fuzz sites are not held paused for long
        t.operator(rng.choices(["pause", "resume", "abort", "status"], weights=[1, 3, 1, 1])[0],
                   rng.choice(["fuzz", "fuzzu"]))
    return kind


def run(inputs: int, seed: int, check_every: int, record_every: int,
        progress: float = 30.0) -> dict[str, Any]:
    rng = random.Random(seed)
    crashes = _Crashes()
    logging.getLogger("fresco_bridge").addHandler(crashes)
    logging.getLogger("fresco_bridge").setLevel(logging.WARNING)
    log_lines = _LogLines()
    logging.getLogger().addHandler(log_lines)
    root = Path(tempfile.mkdtemp(prefix="fresco-fuzz-bench-"))
    t = FuzzTarget(root)
    actions: Counter[str] = Counter()
    violations: list[str] = []
    out_of_limit = 0
    checked = 0
    t0 = time.monotonic()
    last_print = t0
    load_start = os.getloadavg()
    try:
        n = 0
        while t.inputs < inputs:
            actions[action(t, rng)] += 1
            n += 1
            for ctrl in t.sent[checked:]:
                if not all(math.isfinite(c) and -LIMIT <= c <= LIMIT for c in ctrl):
                    out_of_limit += 1
            checked = len(t.sent)
            t.checked_sent = checked
            if n % check_every == 0:
                try:
                    t.check(record=n % record_every == 0)
                except AssertionError as exc:
                    violations.append(f"after action {n}: {exc!r}")
            if not t.bridge._thread.is_alive():
                violations.append(f"bridge thread died after action {n}")
                break
            now = time.monotonic()
            if now - last_print >= progress:
                last_print = now
                print(f"[{now - t0:7.0f} s] {t.inputs} inputs, {n} actions, "
                      f"{t.good_sessions} good sessions, {len(t.sent)} commands forwarded, "
                      f"peak fds {t.peak_fds}, peak RSS {t.peak_rss >> 20} MiB, "
                      f"crashes {len(crashes.records)}, violations {len(violations)}",
                      flush=True)
        try:
            t.check(record=True)  # the final full check, record included
        except AssertionError as exc:
            violations.append(f"final check: {exc!r}")
        record_bytes = (t.run_dir / "record.jsonl").stat().st_size
        opened = Counter(r["site"] for r in read_record(t.run_dir)
                         if r.get("event") == "session-open")
        refused = t.bridge.call(lambda: {name: dict(site.status().get("refused", {}))
                                         for name, site in t.bridge.bridge.sites.items()})
    finally:
        elapsed = time.monotonic() - t0
        t.close()
        logging.getLogger("fresco_bridge").removeHandler(crashes)
        logging.getLogger().removeHandler(log_lines)
    return {
        "seed": seed, "inputs": t.inputs, "actions": n, "actions_by_kind": dict(actions),
        "elapsed_s": round(elapsed, 1), "inputs_per_s": round(t.inputs / elapsed, 1),
        "good_sessions_served": t.good_sessions, "commands_forwarded": len(t.sent),
        "commands_out_of_limit_or_non_finite": out_of_limit,
        "crashes_internal_errors": len(crashes.records), "crash_messages": crashes.records[:5],
        "invariant_violations": len(violations), "violation_messages": violations[:5],
        "fds_baseline": t.baseline_fds, "fds_peak": t.peak_fds,
        "rss_baseline_mib": round(t.baseline_rss / 2**20, 1),
        "rss_peak_mib": round(t.peak_rss / 2**20, 1),
        "record_bytes": record_bytes, "sessions_opened_by_site": dict(opened),
        "refused_by_site": refused,
        "control_lines_unanswered": actions["control-unanswered"],
        "log_lines": log_lines.lines, "log_lines_bad": len(log_lines.bad),
        "log_bad_samples": log_lines.bad[:5],
        "load_average_start": load_start, "load_average_end": os.getloadavg(),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--inputs", type=int, default=100_000)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--check-every", type=int, default=20,
                    help="actions between two full invariant checks")
    ap.add_argument("--record-every", type=int, default=2000,
                    help="actions between two parses of the whole record")
    ap.add_argument("--json", type=Path, default=None, help="also write the summary here")
    ap.add_argument("--quick", action="store_true", help="5000 inputs")
    args = ap.parse_args(argv)
    if args.quick:
        args.inputs, args.record_every = min(args.inputs, 5000), min(args.record_every, 1000)
    summary = run(args.inputs, args.seed, args.check_every, args.record_every)
    text = json.dumps(summary, indent=2)
    print(text)
    if args.json is not None:
        args.json.write_text(text + "\n", encoding="utf-8")
    bad = (summary["commands_out_of_limit_or_non_finite"] or summary["crashes_internal_errors"]
           or summary["invariant_violations"] or summary["log_lines_bad"]
           or summary["control_lines_unanswered"])
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
