"""``python -m fresco_bridge.lab --guard PARENT -- CMD...``: the per-service guard of lab up."""

import sys

from .processes import guard_main

if sys.argv[1:2] == ["--guard"]:
    raise SystemExit(guard_main(sys.argv[2:]))
raise SystemExit("usage: python -m fresco_bridge.lab --guard PARENT_PID -- COMMAND [ARGS...]")
