"""The progress display: a rich bar on a real terminal, quiet off one, ended before an error."""

from __future__ import annotations

import io
import re
import sys

from fresco_bridge.progress import ProgressBar
from tests.support.terminal import run_on_terminal

_BAR = """
import sys, time
from fresco_bridge.exit_codes import exit_code
from fresco_bridge.progress import ProgressBar

def work() -> int:
    bar = ProgressBar("demo", 40, rate_unit="steps", min_interval=0.0)
    for i in range(1, 41):
        time.sleep(0.002)
        bar(i)
        if i == int(sys.argv[1]):
            raise RuntimeError("the rig went away")
    print("after the bar")
    return 0

sys.exit(exit_code(work))
"""


def test_on_a_terminal_the_bar_is_rich_and_ends_its_line() -> None:
    rc, out = run_on_terminal([sys.executable, "-c", _BAR, "0"])
    text = out.decode()
    assert rc == 0, text
    assert "━" in text and "40/40" in text and "steps/s" in text  # rich's bar, the rate
    assert "\x1b[?25h" in text  # the cursor is shown again
    assert re.search(r"40/40[^\n]*\r?\n(\x1b\[\?25h)?after the bar", text), text


def test_on_a_terminal_a_failure_ends_the_bar_before_the_error_line() -> None:
    rc, out = run_on_terminal([sys.executable, "-c", _BAR, "7"])
    text = out.decode()
    assert rc == 1, text
    assert "7/40" in text and "\x1b[?25h" in text
    # the error starts its own line, after the bar's last draw and the restored cursor
    assert re.search(r"\n(\x1b\[\?25h)?error: RuntimeError: the rig went away", text), text
    assert text.index("\x1b[?25h") < text.index("error: RuntimeError")


def test_off_a_terminal_it_prints_sparse_plain_lines() -> None:
    out = io.StringIO()
    bar = ProgressBar("fit", 20, stream=out, rate_unit="steps")
    for i in range(1, 21):
        bar(i)
    lines = out.getvalue().splitlines()
    assert len(lines) == 1, lines  # nothing but the end within the first log_every s
    assert re.fullmatch(r"fit: 20/20 done in \d+\.\d s \([\d,]+ steps/s\)", lines[0]), lines
    bar(20)  # a call after the end prints nothing more
    assert len(out.getvalue().splitlines()) == 1
    out = io.StringIO()
    often = ProgressBar("fit", 4, stream=out, log_every=0.0)
    for i in range(1, 5):
        often(i)
    lines = out.getvalue().splitlines()
    assert [line.split(",")[0] for line in lines[:3]] == ["fit: 1/4", "fit: 2/4", "fit: 3/4"]
    assert "elapsed" in lines[0] and lines[3].startswith("fit: 4/4 done in "), lines
    silent = io.StringIO()
    ProgressBar("x", 3, stream=silent, enabled=False)(3)
    assert silent.getvalue() == ""


_LOGGING = """
import logging, sys, time
from fresco_bridge.progress import ProgressBar

logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(levelname)s %(message)s")
bar = ProgressBar("demo", 30, min_interval=0.05)
for i in range(1, 31):
    time.sleep(0.01)
    bar(i)
    if i == 15:
        logging.getLogger("bridge").warning("a log line in the middle")
logging.getLogger("bridge").warning("a log line after")
"""


def test_a_log_line_during_the_bar_gets_its_own_line() -> None:
    rc, out = run_on_terminal([sys.executable, "-c", _LOGGING])
    plain = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", out.decode())
    assert rc == 0, plain
    # above the bar, never glued to the end of its line ("... leftWARNING ...")
    assert re.search(r"(^|[\r\n])WARNING a log line in the middle\r?\n", plain), repr(plain)
    assert re.search(r"30/30[^\n]*\r?\nWARNING a log line after", plain), repr(plain)
