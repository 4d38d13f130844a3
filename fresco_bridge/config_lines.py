"""Where in a lab TOML file a configuration error is: its line and the site's name.

``tomllib`` keeps no positions, and pydantic reports a location as keys and list indices
(``sites.0.controller``), which is not what a person edits: they look for the site by its name
and go to a line. ``locate`` finds, in the text, the table a location names (the i-th
``[[sites]]``, ``[bridge]``) and within it the deepest key or sub-table of the location that
is written there (in a list of tables such as ``[[sites.limits]]``: its first, an
approximation). Pure text work: table headers and ``key =`` lines, no TOML parsing of its own.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

__all__ = ["locate"]

_HEADER = re.compile(r"^\s*\[\[?\s*([A-Za-z0-9_.\-\"' ]+?)\s*\]\]?\s*(#.*)?$")


def _headers(lines: Sequence[str]) -> list[tuple[int, str]]:
    """(0-based line, dotted table name) of every table header."""
    found = []
    for n, line in enumerate(lines):
        m = _HEADER.match(line)
        if m:
            found.append((n, m.group(1).replace(" ", "").replace('"', "").replace("'", "")))
    return found


def _key_line(lines: Sequence[str], start: int, end: int, key: str) -> int | None:
    assign = re.compile(rf"^\s*[\"']?{re.escape(key)}[\"']?\s*=")
    for n in range(start, end):
        if assign.match(lines[n]):
            return n
    return None


def locate(text: str, raw: dict[str, Any], loc: Sequence[str | int]) -> str:
    """Where ``loc`` is, as a person looks for it: ``line 12 (site damper)`` (the site by its
    name, the 1-based line of the deepest part of ``loc`` written in ``text``), or what of it
    is known; "" when nothing is."""
    label, line = _locate(text, raw, loc)
    return ", ".join(p for p in (f"line {line}" if line is not None else "", label) if p)


def _locate(text: str, raw: dict[str, Any], loc: Sequence[str | int]) -> tuple[str, int | None]:
    lines = text.splitlines()
    headers = _headers(lines)
    words = [str(p) for p in loc]
    if len(loc) >= 2 and loc[0] == "sites" and isinstance(loc[1], int):
        sites = raw.get("sites")
        entry = sites[loc[1]] if isinstance(sites, list) and loc[1] < len(sites) else None
        name = entry.get("name") if isinstance(entry, dict) else None
        where = f"site {name}" if isinstance(name, str) else ""
        rest = [w for w in words[2:] if not w.isdigit()]  # a list index: no header names it
        starts = [n for n, h in headers if h == "sites"]
        if loc[1] >= len(starts):
            return where, None
        start = starts[loc[1]]
        end = next((n for n in starts if n > start), len(lines))
        table = "sites"
    else:
        rest = [w for w in words if not w.isdigit()]
        top = [(n, h) for n, h in headers if rest and h == rest[0]]
        if not top:
            return "", None
        start = top[0][0]
        end = next((n for n, h in headers if n > start and "." not in h), len(lines))
        table, rest, where = rest[0], rest[1:], ""
    line = start
    for depth, key in enumerate(rest):
        sub = f"{table}.{'.'.join(rest[:depth + 1])}"
        header = next((n for n, h in headers if start <= n < end and h == sub), None)
        found = header if header is not None else _key_line(lines, line + 1, end, key)
        if found is None:
            break
        line = found
    return where, line + 1
