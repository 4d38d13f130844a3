"""What a diagnosis returns: the :class:`Diagnosis`, typed, and its JSON document.

Every stage of ``verdict.diagnose`` (read → split → baseline → candidates → selection →
magnitude and shrink → localisation) leaves its part here, and every output reads it from
here: the terminal summary, ``diagnosis.json``, the plots, the run report and the benches.
``Diagnosis.to_json`` is the documented schema (``docs/diagnosis.md``, "What it prints and
writes"; :data:`SCHEMA`), ``Diagnosis.from_json`` reads it back (the arrays the plots draw,
:class:`Series`, are not part of it). Sections whose keys the schema documents one by one
(record, baseline, noise floor, localisation, candidate rows) stay JSON objects; the verdict,
which every reader branches on, is a :class:`Verdict`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["NOT_AN_EFFECT", "SCHEMA", "Diagnosis", "Series", "Verdict", "json_ready"]

FloatArray = npt.NDArray[np.float64]

SCHEMA = "fresco-bridge/diagnosis/2"
OLDER_SCHEMAS = frozenset({"fresco-bridge/diagnosis/1"})
"""Documents still read: schema 1 is schema 2 without ``interface_gap`` (read as None)."""
NOT_AN_EFFECT = frozenset({"none", "unexplained", "baseline_misfit"})
"""Verdicts that add no effect to the sim."""


@dataclass(frozen=True)
class Verdict:
    """Which effect the record names, how sure it is, and the figures it quotes (its winner's
    row on ``gap_basis``: as measured, ``raw``, or with the white noise removed,
    ``systematic``)."""

    effect: str
    """An effect name, ``a+b`` for a pair, ``none``, ``baseline_misfit`` or ``unexplained``."""
    confidence: float
    explanation: str
    gap_before_pct: float
    gap_after_pct: float | None
    shrink_pct: float | None
    gap_basis: str = "raw"
    confidence_words: str = ""
    runner_up: str | None = None
    not_separated_from: str | None = None
    flags: dict[str, str] = field(default_factory=dict)
    better_family: str | None = None
    stories: list[dict[str, Any]] = field(default_factory=list)
    """Two stories the withheld evidence cannot separate, the winner first, each with its
    weight (BIC weights of the two, summing to 1) and its ΔBIC; empty for one story."""
    separated_by: str | None = None
    """For two stories: the measurement that would separate them."""

    @property
    def label(self) -> str:
        """The name a bench scores: the effect, or ``a|b`` for two stories."""
        if len(self.stories) > 1:
            return "|".join(str(s["effect"]) for s in self.stories)
        return self.effect

    @property
    def adds_an_effect(self) -> bool:
        return self.effect not in NOT_AN_EFFECT

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> Verdict:
        """From the verdict's JSON object (unknown keys are an error: one schema)."""
        known = {f.name for f in fields(cls)}
        extra = set(doc) - known
        if extra:
            raise ValueError(f"verdict: unknown key(s) {', '.join(sorted(extra))}")
        return cls(**{k: v for k, v in doc.items() if k in known})


@dataclass(frozen=True)
class Series:
    """The arrays the plots draw, per sample of the record (not in the JSON)."""

    time: FloatArray
    cmd: FloatArray
    meas_disp: FloatArray | None
    force: FloatArray
    sim: FloatArray
    """The baseline's predicted force (fitted on the calibration part, the whole record)."""
    sim_disp: FloatArray | None
    best: FloatArray | None
    """The winner's predicted force (None when the verdict names no candidate)."""
    best_disp: FloatArray | None
    stop: int
    """The first withheld sample."""


@dataclass(frozen=True)
class Diagnosis:
    """One record's diagnosis (the sections of ``docs/diagnosis.md``'s schema)."""

    record: dict[str, Any]
    baseline: dict[str, Any]
    noise_floor: dict[str, Any]
    localization: dict[str, Any]
    effects: list[dict[str, Any]]
    """One row per single candidate, best score first."""
    pairs: list[dict[str, Any]]
    families: list[dict[str, Any]]
    verdict: Verdict
    not_identifiable: dict[str, str]
    """Candidates the record cannot identify (no command channel), with the reason."""
    hidden: list[str]
    seconds: float
    interface_gap: dict[str, Any] | None = None
    """Target vs measured displacement of a run with displacement correction, and against the
    uncorrected run (``diagnosis/interface_gap.py``); None for a record without them."""
    series: Series | None = field(default=None, compare=False)

    def winner(self) -> dict[str, Any] | None:
        """The candidate row the verdict names (None for a verdict that names none)."""
        return next((e for e in [*self.effects, *self.pairs]
                     if e["name"] == self.verdict.effect), None)

    def to_json(self) -> dict[str, Any]:
        """The JSON document (:data:`SCHEMA`): finite numbers, ``null`` for the rest."""
        out: dict[str, Any] = {"schema": SCHEMA}
        for f in fields(self):
            if f.name == "series":
                continue
            value = getattr(self, f.name)
            out[f.name] = asdict(value) if isinstance(value, Verdict) else value
        cleaned: dict[str, Any] = json_ready(out)
        return cleaned

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> Diagnosis:
        """The diagnosis a JSON document holds (no :class:`Series`); ValueError when it is not
        this schema's."""
        if doc.get("schema") in OLDER_SCHEMAS:
            doc = {**doc, "schema": SCHEMA, "interface_gap": None}
        if doc.get("schema") != SCHEMA:
            raise ValueError(f"not a diagnosis document: schema {doc.get('schema')!r} "
                             f"(expected {SCHEMA!r})")
        names = {f.name for f in fields(cls)} - {"series"}
        missing = names - set(doc)
        if missing:
            raise ValueError(f"diagnosis document lacks {', '.join(sorted(missing))}")
        values = {k: doc[k] for k in names}
        values["verdict"] = Verdict.from_json(doc["verdict"])
        return cls(**values)


def json_ready(obj: Any) -> Any:
    """``obj`` with numpy scalars as Python numbers, non-finite floats as None, tuples as
    lists, a :class:`Diagnosis` as its document, and private keys (``_…``) left out."""
    if isinstance(obj, Diagnosis):
        return obj.to_json()
    if isinstance(obj, Mapping):
        return {k: json_ready(v) for k, v in obj.items() if not str(k).startswith("_")}
    if isinstance(obj, list | tuple):
        return [json_ready(v) for v in obj]
    if isinstance(obj, float | np.floating):
        value = float(obj)
        return value if math.isfinite(value) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.ndarray):
        return json_ready(obj.tolist())
    return obj
