"""The two-story OpenSeesPy frame of examples/opensees_two_story.py, each story's specimen behind
a lab controller server that speaks OpenFresco's ``expControl GenericTCP`` protocol — the way
labs connected LabVIEW or real-time targets to OpenFresco, unchanged. Two simulated servers:

    .venv/bin/sim-actuator serve --protocol generic-tcp --port 5022 --preset ideal-bilinear # 1
    .venv/bin/sim-actuator serve --protocol generic-tcp --port 5023 --preset ideal-elastic # 2
    .venv/bin/fresco-bridge serve --config examples/generic_tcp.toml                       # 3
    .venv/bin/python examples/opensees_generic_tcp.py                                      # 4

Kill a server mid-run (Ctrl-C in its terminal) and start it again: the bridge waits for it
(``controller_recovery``), reads it first over the new link and sends the same setpoint once —
no step lost. The frame, the record and the options (--record, --pga, --steps, --ports) are
examples/opensees_two_story.py's. Units: mm, kN, s. Story 1: site damper (port 8094), story 2:
site story2 (port 8095).
"""

from __future__ import annotations

import sys

from opensees_two_story import main  # the frame beside this file (examples/ is on sys.path)

if __name__ == "__main__":
    sys.exit(main(doc=__doc__, ports=(8094, 8095), config="examples/generic_tcp.toml",
                  next_step=".venv/bin/fresco-bridge runs list   # the run the bridge recorded"))
