"""The one list of site kinds; the config's discriminated union on ``[[sites]] kind``, its
error texts, the daemon's factories and the configuration table of docs/configuration.md
derive from it.

Adding a kind: one new module (its config model, a ``SiteConfigBase`` subclass; its group
factory; ``KIND``) plus one line below. Every kind's sites are ``Site``s sharing the site core
(``sites/core.py``): the daemon, ``ctl``, the transports and telemetry know nothing narrower.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from .sites.experimental_kind import KIND as EXPERIMENTAL
from .sites.kind import SiteKind
from .twins.kind import KIND as UPDATABLE

__all__ = ["SITE_KINDS", "known_site_kinds", "site_kind", "site_kinds_markdown"]

SITE_KINDS: Mapping[str, SiteKind] = MappingProxyType({kind.name: kind for kind in (
    EXPERIMENTAL,
    UPDATABLE,
)})  # fmt: skip
"""Site kind name -> its declaration, in documentation order (``experimental`` is the
default)."""

DEFAULT_KIND = "experimental"


def known_site_kinds() -> str:
    """``experimental or updatable``: the kinds, as error texts name them."""
    names = list(SITE_KINDS)
    return ", ".join(names[:-1]) + f" or {names[-1]}" if len(names) > 1 else names[0]


def site_kind(name: str) -> SiteKind:
    """The declaration of kind ``name``, or ``ValueError`` naming the kinds there are."""
    try:
        return SITE_KINDS[name]
    except KeyError:
        raise ValueError(f"unknown site kind {name!r}; expected {known_site_kinds()}") from None


def site_kinds_markdown() -> str:
    """docs/configuration.md's table cell for ``sites.kind``."""
    return "<br>".join(f"`{kind.name}`: {kind.summary}" for kind in SITE_KINDS.values())
