"""Keys of a model file section that this version knows: typos refused, other keys tolerated.

The model file may be shared with other tools (DESIGN.md: more keys welcome), so an unknown
key is not an error unless it is close to a known one, which makes it a typo.
"""

from __future__ import annotations

import difflib
import logging
from collections.abc import Iterable, Mapping
from typing import Any

from fdi_daemon.errors import ConfigError

__all__ = ["close_match", "known_settings", "split_known"]

log = logging.getLogger("fdi.model")


def close_match(key: object, known: Iterable[str]) -> str | None:
    """The known key that ``key`` is most likely a typo of (difflib ratio >= 0.8), or None."""
    close = difflib.get_close_matches(str(key), [str(k) for k in known], n=1, cutoff=0.8)
    return close[0] if close else None


def split_known(
    mapping: Mapping[str, Any] | None,
    known: Iterable[str],
    where: str,
    noun: str = "setting",
    fate: str = "ignoring",
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The entries of ``mapping`` split into (known, unknown). An unknown key close to a
    known one is a typo: ConfigError naming both. Any other unknown key is logged as a
    warning ("<where>: <fate> <noun> 'x', which this version does not know")."""
    known = [str(k) for k in known]
    inside: dict[str, Any] = {}
    outside: dict[str, Any] = {}
    for key, value in dict(mapping or {}).items():
        if key in known:
            inside[key] = value
            continue
        close = close_match(key, known)
        if close:
            raise ConfigError(f"{where}: unknown {noun} {key!r} (did you mean {close!r}?)")
        log.warning("%s: %s %s %r, which this version does not know", where, fate, noun, key)
        outside[key] = value
    return inside, outside


def known_settings(
    mapping: Mapping[str, Any] | None, known: Iterable[str], where: str
) -> dict[str, Any]:
    """The entries of a settings mapping that this version knows (`split_known`); the
    others are ignored with a warning."""
    return split_known(mapping, known, where)[0]
