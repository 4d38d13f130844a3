"""The models' public contract: factory, parameter documentation, errors, protocol, clones."""

from __future__ import annotations

import ast
import inspect
import math
from pathlib import Path
from typing import Any, NamedTuple

import pytest

import sim_actuator.checks as checks
import sim_actuator.models as models
import sim_actuator.models.base as models_base
from sim_actuator.checks import POSITIVE
from sim_actuator.models import (
    MODEL_DEFAULTS,
    MODEL_KINDS,
    MODEL_PARAMETERS,
    Bilinear,
    BilinearState,
    BoucWen,
    BoucWenBaberNoori,
    Elastic,
    HysteresisBase,
    HysteresisModel,
    MenegottoPinto,
    ModelInputError,
    ModelKind,
    ModelParameterError,
    Param,
    ParametricModel,
    make_model,
    model_kind,
)

CLASSES: dict[str, type[Any]] = {
    "elastic": Elastic,
    "bilinear": Bilinear,
    "bouc-wen": BoucWen,
    "bwbn": BoucWenBaberNoori,
    "menegotto-pinto": MenegottoPinto,
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
    "menegotto-pinto": {"k0": 8.0, "fy": 12.0, "alpha": 0.03, "R0": 10.0, "a1": 0.02, "a3": 0.02},
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


# -- the registry, the state base, state() and with_params() ------------------------------------


def test_registry_lists_every_kind_with_its_class_and_parameters() -> None:
    assert list(MODEL_KINDS) == list(CLASSES)
    for name, kind in MODEL_KINDS.items():
        assert kind.cls is CLASSES[name] and kind.name == name == kind.cls.name
        assert list(MODEL_PARAMETERS[name]) == [p.name for p in kind.params]
        assert kind.summary and "\n" not in kind.summary
        for param in kind.params:
            assert param.unit and param.meaning
    assert MODEL_PARAMETERS["bilinear"]["alpha"] == (
        "post-yield to initial stiffness ratio, dimensionless, 0 <= alpha < 1"
    )
    assert MODEL_PARAMETERS["bouc-wen"]["A"].endswith("> 0 (default 1)")
    assert model_kind("bwbn").cls is BoucWenBaberNoori
    with pytest.raises(ModelParameterError, match="unknown model kind 'x'"):
        model_kind("x")


def test_base_does_not_import_the_kinds() -> None:
    """No circle: the base (and the checks it uses) import no model module; the registry does."""
    imported: set[str] = set()
    for module in (models_base, checks):
        tree = ast.parse(Path(inspect.getfile(module)).read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module:
                imported.add(node.module)
            elif isinstance(node, ast.Import):
                imported.update(alias.name for alias in node.names)
    assert not {m for m in imported if m.startswith("sim_actuator.models")}, imported


def test_a_new_kind_is_one_class_declaring_name_params_state() -> None:
    class DoubleState(NamedTuple):
        d: float
        f: float

    class Double(HysteresisBase):
        """Test kind: f = 2*s*d."""

        __slots__ = ("s",)
        name = "double"
        PARAMS = (Param("s", "scale", "-", POSITIVE, 1.0),)
        STATE = DoubleState
        s: float

        def __init__(self, *, s: float = 1.0) -> None:
            self._init_params(s=s)
            self._start()

        def _virgin(self) -> tuple[float, ...]:
            return (0.0, 0.0)

        def set_trial(self, d: float) -> tuple[float, float]:
            self._trial = (d, 2 * self.s * d)
            return 2 * self.s * d, 2 * self.s

        @property
        def initial_tangent(self) -> float:
            return 2 * self.s

    kind = ModelKind(Double)
    model = kind.build({"s": 3.0})
    assert isinstance(model, ParametricModel)
    assert model.set_trial(1.0) == (6.0, 6.0)
    model.commit()
    assert model.state() == DoubleState(1.0, 6.0)
    assert kind.defaults == {"s": 1.0}
    assert kind.summary.startswith("The models' public contract")  # its module's docstring
    with pytest.raises(ModelParameterError, match=r"double: s must be > 0, got -1"):
        kind.build({"s": -1})
    with pytest.raises(ModelParameterError, match=r"double: unknown parameter\(s\) t"):
        kind.build({"t": 1.0})


def _loaded(kind: str, steps: int = 30) -> HysteresisBase:
    scale = VALID[kind].get("fy", 1.0) / VALID[kind].get("k0", 1.0)
    model = make_model(kind, **VALID[kind])
    assert isinstance(model, HysteresisBase)
    for d in history(scale)[:steps]:
        model.set_trial(d)
        model.commit()
    return model


@pytest.mark.parametrize("kind", sorted(CLASSES))
def test_state_is_the_committed_state_as_an_immutable_value(kind: str) -> None:
    model = _loaded(kind)
    state = model.state()
    assert type(state) is MODEL_KINDS[kind].cls.STATE
    assert state[0] == model.committed[0]
    assert hash(state) == hash(model.state())  # immutable: hashable, equal on re-read
    with pytest.raises(AttributeError):
        state.d = 1.0  # type: ignore[misc]
    model.set_trial(123.0 * state[0] + 0.5)  # a trial does not change the committed state
    assert model.state() == state
    model.revert_to_start()
    assert model.state() != state and model.state()[0] == 0.0


@pytest.mark.parametrize("kind", sorted(CLASSES))
def test_with_params_and_state_continues_bit_for_bit(kind: str) -> None:
    """The UKF's use: ``model.with_params(p, s).set_trial(d)`` from a committed state."""
    model = _loaded(kind)
    scale = VALID[kind].get("fy", 1.0) / VALID[kind].get("k0", 1.0)
    twin = model.with_params(model.parameters, model.state())
    assert type(twin) is type(model) and twin is not model
    assert twin.committed == model.committed and twin.state() == model.state()
    for d in history(scale)[30:]:
        assert twin.set_trial(d) == model.set_trial(d)
        twin.commit()
        model.commit()


@pytest.mark.parametrize("kind", sorted(CLASSES))
def test_with_params_builds_an_independent_model_of_new_parameters(kind: str) -> None:
    model = _loaded(kind)
    state = model.state()
    name = MODEL_KINDS[kind].params[0].name
    changed = {name: VALID[kind][name] * 1.5}
    other = model.with_params(changed, state)
    assert other.parameters == {**model.parameters, **changed}
    assert other.state() == state
    probe = state[0] + 0.3 * (VALID[kind].get("fy", 1.0) / VALID[kind].get("k0", 1.0))
    fresh = make_model(kind, **{**VALID[kind], **changed}).with_params({}, state)
    assert other.set_trial(probe) == fresh.set_trial(probe)
    other.commit()
    assert model.state() == state  # the original is untouched
    virgin = model.with_params(changed)
    assert virgin.committed == (0.0, 0.0)
    assert virgin.parameters == make_model(kind, **{**VALID[kind], **changed}).parameters


def test_with_params_keeps_the_integration_setting() -> None:
    model = BoucWen(**VALID["bouc-wen"], dz_max=0.001)  # type: ignore[arg-type]
    assert model.with_params({"n": 3.0}).dz_max == 0.001


def test_with_params_refuses_bad_parameters_and_foreign_states() -> None:
    bilinear = _loaded("bilinear")
    with pytest.raises(ModelParameterError, match=r"bilinear: unknown parameter\(s\) k"):
        bilinear.with_params({"k": 1.0})
    with pytest.raises(ModelParameterError, match=r"bilinear: fy must be > 0, got -1\.0"):
        bilinear.with_params({"fy": -1.0})
    with pytest.raises(ModelParameterError, match=r"state must be a BilinearState .* got "
                       r"BoucWenState"):
        bilinear.with_params({}, _loaded("bouc-wen").state())
    with pytest.raises(ModelParameterError, match=r"state must be a BilinearState .* got tuple"):
        bilinear.with_params({}, (0.0, 0.0, 1.0))
    nan_state = BilinearState(0.0, math.nan, 1.0)
    with pytest.raises(ModelParameterError, match=r"state\.f must be finite, got nan"):
        bilinear.with_params({}, nan_state)
