"""The OpenFresco captures the protocol tests replay are committed, complete and unedited.

They used to be read from ``../shared`` and 94 tests skipped without it; now a missing or
changed capture fails here (``SHA256SUMS`` beside them), rather than silently shrinking the
parametrised tests that glob the folder.
"""

from __future__ import annotations

import hashlib

from tests.support.paths import OPENFRESCO_CAPTURES, REPO


def _listed() -> dict[str, str]:
    lines = (OPENFRESCO_CAPTURES / "SHA256SUMS").read_text(encoding="utf-8").splitlines()
    return {name.strip(): digest for digest, name in (ln.split(maxsplit=1) for ln in lines)}


def test_the_captures_live_in_the_repository() -> None:
    assert OPENFRESCO_CAPTURES.is_relative_to(REPO / "tests")
    assert (OPENFRESCO_CAPTURES / "README.md").is_file()


def test_every_capture_is_listed_and_matches_its_checksum() -> None:
    listed = _listed()
    present = sorted(p.name for p in OPENFRESCO_CAPTURES.glob("*.json"))
    assert present == sorted(listed), "captures and SHA256SUMS disagree"
    assert len(present) == 12
    changed = [name for name in present if hashlib.sha256(
        (OPENFRESCO_CAPTURES / name).read_bytes()).hexdigest() != listed[name]]
    assert not changed, f"edited captures (restore them from git): {changed}"
