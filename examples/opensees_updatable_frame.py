"""An OpenSeesPy frame whose story-2 damper is the online-updated twin of the tested story-1
damper: both are genericClient elements; the bridge serves the tested one from an experimental
site and the twin from an updatable site that learns from it.

    .venv/bin/fresco-bridge serve --config examples/updatable_twin.toml   # terminal 1
    .venv/bin/python examples/opensees_updatable_frame.py                 # terminal 2
    .venv/bin/fresco-bridge ctl --site twin1 status                       # the twin's learner

The frame, the record (examples/data/RSN960_NORTHR_LOS270.AT2, PGA 3 m/s^2) and the options
(--record, --pga, --steps, --ports) are examples/opensees_two_story.py's.
Units: mm, kN, s. Story 1: the tested damper (site damper, port 8092); story 2: its twin (site
twin1, port 8093).
"""

from __future__ import annotations

import sys

from opensees_two_story import main  # the frame beside this file (examples/ is on sys.path)

if __name__ == "__main__":
    sys.exit(main(doc=__doc__, ports=(8092, 8093), config="examples/updatable_twin.toml",
                  next_step=".venv/bin/fresco-bridge ctl --site twin1 status   # the learner"))
