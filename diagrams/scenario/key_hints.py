"""The hint an unknown scenario key's message ends with: the closest valid key or section,
or, for a section that exists without that key, the keys the section has."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

__all__ = ["unknown_key_hint"]


def unknown_key_hint(key: str, valid: Iterable[str]) -> str:
    """'; did you mean ...?', '; SECTION has A, B, ...' or '' for `key`, among the dotted
    keys `valid` (e.g. "wall.stiffness")."""
    valid = list(valid)
    # Candidates: every full key and every section ("wall", "admittance", ...).
    sections = {k.rsplit(".", i)[0] for k in valid for i in range(1, k.count(".") + 1)}
    section = key.rpartition(".")[0]
    members = sorted(k[len(section) + 1 :] for k in valid if k.startswith(section + "."))
    close = difflib.get_close_matches(key, valid + sorted(sections), n=1, cutoff=0.5)
    if members and (not close or close[0] == section):  # a section without this key
        return f"; {section} has {', '.join(members)}"
    return f"; did you mean '{close[0]}'?" if close else ""
