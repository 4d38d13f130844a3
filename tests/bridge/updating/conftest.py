"""The updating tests' shared fixture: a small network pre-trained on a BWBN history."""

from __future__ import annotations

import dataclasses

import pytest

from fresco_bridge.updating.ann import PRETRAIN_LM, AnnModel, pretrain
from tests.support.histories import disp_history, force_history


@pytest.fixture(scope="session")
def small_ann() -> AnnModel:
    """A paper-shaped net (6-10-10-10-1) pre-trained briefly on 300 BWBN samples."""
    d = disp_history(300, seed=11, amp=3.0)
    return pretrain(d, force_history(d), seed=3,
                    options=dataclasses.replace(PRETRAIN_LM, max_iterations=30))
