"""One check of OpenSees uniaxial-material semantics, for every twin a test builds."""

from __future__ import annotations

from sim_actuator.models import HysteresisModel


def assert_material_semantics(twin: HysteresisModel) -> None:
    """Trials start from the last commit (repeatable, never advance it), revert and clone keep
    the committed state, revert_to_start returns to (0, 0). Leaves the twin virgin."""
    for d in (0.5, 2.0, 1.0):
        twin.set_trial(d)
        twin.commit()
    committed = twin.committed
    first = twin.set_trial(3.0)
    for d in (-5.0, 7.0, 3.3):
        twin.set_trial(d)
    assert twin.committed == committed
    assert twin.set_trial(3.0) == first
    twin.revert_to_last_commit()
    assert twin.committed == committed
    clone = twin.clone()
    twin.set_trial(4.0)
    twin.commit()
    assert clone.committed == committed
    twin.revert_to_start()
    assert twin.committed == (0.0, 0.0)
