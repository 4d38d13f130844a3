"""The three-actuator column the rig tests share: ``ThreeActuators2d`` with one horizontal
actuator and two vertical ones under a loading beam, 400 mm left and 600 mm right."""

from __future__ import annotations

L1, L2 = 400.0, 600.0
LINEAR_T = ((1.0, 0.0, 0.0), (0.0, 1.0, -L1), (0.0, 1.0, L2))
"""J(0): strokes per unit (u, v, θ) at rest."""


def three_actuators_2d(nl_geom: bool) -> str:
    """The column's ``[sites.setup]`` table."""
    return f"""[sites.setup]
kind = "ThreeActuators2d"
La1 = 1000.0
La2 = 800.0
La3 = 800.0
L1 = {L1}
L2 = {L2}
nlGeom = {str(nl_geom).lower()}
"""
