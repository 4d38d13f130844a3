"""The models' public contract: factory, parameter documentation, errors, protocol, clones."""

from __future__ import annotations

import inspect
import math
from typing import Any

import pytest

import sim_actuator.models as models
from sim_actuator.models import (
    MODEL_DEFAULTS,
    MODEL_PARAMETERS,
    Bilinear,
    BoucWen,
    BoucWenBaberNoori,
    Elastic,
    HysteresisModel,
    ModelInputError,
    ModelParameterError,
    make_model,
)

CLASSES: dict[str, type[Any]] = {
    "elastic": Elastic,
    "bilinear": Bilinear,
    "bouc-wen": BoucWen,
    "bwbn": BoucWenBaberNoori,
}
VALID: dict[str, dict[str, float]] = {
    "elastic": {"k": 5.0},
    "bilinear": {"k0": 68000.0, "fy": 35000.0, "alpha": 0.008},
    "bouc-wen": {"k0": 20.0, "fy": 4.0, "alpha": 0.1, "n": 2.0, "beta": 0.5, "gamma": 0.5},
    "bwbn": {
        "k0": 20.0, "fy": 4.0, "alpha": 0.1, "n": 2.0, "beta": 0.5, "gamma": 0.5,
        "zeta_s": 0.5, "p": 1.0, "q": 0.1, "psi0": 0.3, "delta_psi": 0.01, "lam": 0.5,
        "delta_nu": 0.01,
    },
}  # fmt: skip


def history(scale: float) -> list[float]:
    return [scale * 2.5 * math.sin(0.3 * i) * (1.0 + 0.02 * i) for i in range(1, 60)]


def test_package_keeps_its_docstring_and_exports() -> None:
    assert models.__doc__ == "Hysteresis models of specimens, pure and deterministic."
    for name in ("make_model", "MODEL_PARAMETERS", "HysteresisModel", "ModelParameterError"):
        assert name in models.__all__


@pytest.mark.parametrize("kind", sorted(CLASSES))
def test_parameter_tables_match_the_constructors(kind: str) -> None:
    signature = inspect.signature(CLASSES[kind])
    keywords = {n: p for n, p in signature.parameters.items() if n != "dz_max"}
    assert set(keywords) == set(MODEL_PARAMETERS[kind])
    defaults = {n: p.default for n, p in keywords.items() if p.default is not p.empty}
    assert defaults == MODEL_DEFAULTS[kind]
    assert all(len(text) > 10 for text in MODEL_PARAMETERS[kind].values())


@pytest.mark.parametrize("kind", sorted(CLASSES))
def test_factory_builds_protocol_conforming_models(kind: str) -> None:
    model = make_model(kind, **VALID[kind])
    assert isinstance(model, CLASSES[kind])
    assert isinstance(model, HysteresisModel)
    assert model.name == kind
    assert model.committed == (0.0, 0.0)
    _, tangent = model.set_trial(1e-9)
    assert tangent == pytest.approx(model.initial_tangent, rel=1e-6)


@pytest.mark.parametrize("kind", sorted(CLASSES))
def test_clone_copies_state_and_is_independent(kind: str) -> None:
    scale = VALID[kind].get("fy", 1.0) / VALID[kind].get("k0", 1.0)
    model = make_model(kind, **VALID[kind])
    path = history(scale)
    for d in path[:30]:
        model.set_trial(d)
        model.commit()
    pending = model.set_trial(path[30])
    twin = model.clone()
    assert type(twin) is type(model)
    twin.commit()  # the pending trial was copied
    assert twin.committed == (path[30], pending[0])
    # diverge the twin; the original must be untouched and continue identically to a fresh run
    for d in path[31:]:
        twin.set_trial(-d)
        twin.commit()
    model.revert_to_last_commit()
    fresh = make_model(kind, **VALID[kind])
    for d in path[:30]:
        fresh.set_trial(d)
        fresh.commit()
    for d in path[30:]:
        assert model.set_trial(d) == fresh.set_trial(d)
        model.commit()
        fresh.commit()


@pytest.mark.parametrize("kind", sorted(CLASSES))
def test_revert_to_start_restores_the_virgin_response(kind: str) -> None:
    scale = VALID[kind].get("fy", 1.0) / VALID[kind].get("k0", 1.0)
    model = make_model(kind, **VALID[kind])
    first = [model.set_trial(d) for d in history(scale)[:5]]
    for d in history(scale):
        model.set_trial(d)
        model.commit()
    model.revert_to_start()
    assert model.committed == (0.0, 0.0)
    assert [model.set_trial(d) for d in history(scale)[:5]] == first


def test_elastic_is_linear() -> None:
    model = Elastic(k=2.5)
    assert model.set_trial(-4.0) == (-10.0, 2.5)
    model.commit()
    assert model.committed == (-4.0, -10.0)
    with pytest.raises(ModelInputError, match="elastic"):
        model.set_trial(math.inf)


def test_unknown_kind_names_the_allowed_kinds() -> None:
    with pytest.raises(ModelParameterError) as err:
        make_model("steel02", k0=1.0)
    message = str(err.value)
    assert "steel02" in message
    assert "bilinear, bouc-wen, bwbn, elastic" in message


def test_unknown_and_missing_parameters_are_named() -> None:
    with pytest.raises(ModelParameterError, match=r"bilinear: unknown parameter\(s\) E0; "
                       r"allowed: k0, fy, alpha") as err:  # fmt: skip
        make_model("bilinear", k0=1.0, fy=1.0, alpha=0.0, E0=3.0)
    assert err.value.parameter == "E0"
    with pytest.raises(ModelParameterError, match=r"bwbn: missing required parameter\(s\) q, lam"):
        make_model("bwbn", **{k: v for k, v in VALID["bwbn"].items() if k not in ("q", "lam")})


@pytest.mark.parametrize(
    ("kind", "changes", "expected"),
    [
        ("bilinear", {"fy": -3}, "bilinear: fy must be > 0, got -3"),
        ("bilinear", {"k0": 0.0}, "bilinear: k0 must be > 0, got 0.0"),
        ("bilinear", {"alpha": 1.0}, "bilinear: alpha must satisfy 0 <= alpha < 1, got 1.0"),
        ("bilinear", {"fy": math.nan}, "bilinear: fy must be finite, got nan"),
        ("bilinear", {"fy": True}, "bilinear: fy must be a real number, got True (bool)"),
        ("bilinear", {"fy": "35"}, "bilinear: fy must be a real number, got '35' (str)"),
        ("elastic", {"k": -1.0}, "elastic: k must be > 0, got -1.0"),
        ("bouc-wen", {"n": 0.5}, "bouc-wen: n must be >= 1, got 0.5"),
        ("bouc-wen", {"beta": 0.0}, "bouc-wen: beta must be > 0, got 0.0"),
        ("bouc-wen", {"gamma": -0.5}, "bouc-wen: beta + gamma must be > 0, got 0.5 + -0.5"),
        ("bouc-wen", {"A": -1.0}, "bouc-wen: A must be > 0, got -1.0"),
        ("bwbn", {"zeta_s": 1.0}, "bwbn: zeta_s must satisfy 0 <= zeta_s < 1, got 1.0"),
        ("bwbn", {"psi0": 0.0}, "bwbn: psi0 must be > 0, got 0.0"),
        ("bwbn", {"lam": -0.1}, "bwbn: lam must be > 0, got -0.1"),
        ("bwbn", {"delta_nu": -0.01}, "bwbn: delta_nu must be >= 0, got -0.01"),
        ("bwbn", {"q": 1.5}, "bwbn: q must satisfy 0 <= q < 1, got 1.5"),
    ],
)
def test_bad_parameter_values_get_specific_messages(
    kind: str, changes: dict[str, Any], expected: str
) -> None:
    with pytest.raises(ModelParameterError) as err:
        make_model(kind, **{**VALID[kind], **changes})
    assert str(err.value) == expected
    assert err.value.model == kind
    assert err.value.parameter == next(iter(changes)) or "beta + gamma" in expected
    assert isinstance(err.value, ValueError)
