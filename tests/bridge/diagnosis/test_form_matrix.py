"""Each effect in the forms a lab meets, on short records (``benchmarks.diagnosis.forms``).

One record per form (1,200 samples, a fixed seed per form), diagnosed blind and scored with the
bench's credit. The forms the selection rule does not yet name right are marked as expected
failures, strictly: a rule that starts naming one fails the test until the mark is removed, so
this list is the measured state, not a wish (``BENCHMARKS.md``, "Diagnosis", bad cases):

* pinching as an elastic slip spring in series is taken for a gap with smooth contact, and as a
  force reduction near zero displacement for a law misfit;
* this short record's linear viscosity (4 % of fy at the RMS velocity) is below what its
  noise lets the record resolve.
"""

from __future__ import annotations

import pytest

from benchmarks.diagnosis.bench import contains_truth
from benchmarks.diagnosis.forms import FORMS, form_record
from fresco_bridge.diagnosis.verdict import diagnose

NOT_YET = {
    "pinching/slip-spring": "named backlash: a slip spring looks like a gap with smooth contact",
    "pinching/near-zero": "named baseline_misfit on this record",
    "rate_dependence/linear": "named none on this short record: 4 % of fy at the RMS velocity "
                              "is below what 1,200 noisy samples resolve",
}


@pytest.mark.parametrize("form", [
    pytest.param(f, marks=pytest.mark.xfail(reason=NOT_YET[f], strict=True)) if f in NOT_YET
    else f for f in FORMS])
def test_each_form_is_named(form: str) -> None:
    seed = 4242 + list(FORMS).index(form)
    rec = form_record(form, seed, steps=1200)
    verdict = diagnose(rec.record).verdict
    # right, or a two-story answer one of whose stories is right (the matrix's figure)
    assert contains_truth(rec.effect, verdict.label), (form, verdict.label, verdict.explanation)


def test_the_matrix_covers_at_least_three_forms_per_effect_the_issue_names() -> None:
    per_effect: dict[str, int] = {}
    for f in FORMS.values():
        per_effect[f.effect] = per_effect.get(f.effect, 0) + 1
    for effect in ("friction", "rate_dependence", "pinching", "actuator_delay", "degradation"):
        assert per_effect[effect] >= 3, effect
    assert per_effect["backlash"] >= 2 and per_effect["sensor_noise"] >= 2
