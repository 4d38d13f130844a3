"""Where things are, for every test: the repository, ``../shared`` beside it, its data."""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
"""The repository's root (``tests/support/paths.py`` -> ``..``/``..``)."""
SHARED = REPO.parent / "shared"
"""``../shared``: specs, captures, data. Tests may read it; the product never needs it."""
OPENFRESCO_CAPTURES = REPO / "tests" / "fixtures" / "openfresco"
"""Byte captures of the real OpenSees / OpenFresco clients (``gc_*.json``, ``site_*.json``),
committed with the tests (their README says where they come from)."""
GROUND_MOTIONS = SHARED / "data" / "ground_motions"
EXAMPLES = REPO / "examples"
DOCKER = REPO / "docker"
