"""One exception hierarchy for flexmb. Messages say where, what was received, what was expected."""

from __future__ import annotations

import os
from pathlib import Path


class FlexmbError(Exception):
    """Base class of every error flexmb raises on purpose."""


class SceneError(FlexmbError):
    """A scene file (or dict) does not match the schema.

    Parameters
    ----------
    where : str
        ``file:key.path`` of the offending entry.
    message : str
        What was received and what was expected.
    """

    def __init__(self, where: str, message: str):
        self.where = where
        super().__init__(f"{where}: {message}")


class ConvergenceError(FlexmbError):
    """A step (or load increment) did not converge and the policy is to stop."""

    def __init__(self, message: str, result=None):
        self.result = result
        super().__init__(message)


# -- bounded excerpts for messages --------------------------------------------------------------
# Every message that shows a user's value goes through :func:`excerpt`, every list of names through
# :func:`name_list`: a scene can hold a million-entry list or an alias bomb, and a message must stay
# a line long and cheap to build (never a full ``repr``).

EXCERPT_CHARS = 80
NAME_LIST_ITEMS = 8


def thousands(n: int) -> str:
    """``199990`` → ``'199 990'`` (a space as the thousands separator, SI style)."""
    return f"{n:,}".replace(",", " ")


def excerpt(value, limit: int = EXCERPT_CHARS) -> str:
    """At most ``limit`` characters showing ``value``. A container shown in part carries its type and
    size (``list of 200 001 items [1, 1, …]``); one shown whole reads as Python (``[1.0, 0.0]``).
    The work is bounded by ``limit`` whatever the value's size (shared or recursive structures too)."""
    if isinstance(value, (list, tuple, dict, set, frozenset)):
        whole = _short(value, limit, 0)
        if "…" not in whole:
            return whole
        n = len(value)
        head = f"{_kind(value)} of {thousands(n)} {'key' if isinstance(value, dict) else 'item'}{'s' if n != 1 else ''} "
        return _cut(head + _short(value, max(limit - len(head), 8), 0), limit)
    return _short(value, limit, 0)


def _kind(value) -> str:
    return {list: "list", tuple: "list", dict: "mapping", set: "set", frozenset: "set"}.get(type(value),
                                                                                            type(value).__name__)


def _cut(text: str, limit: int) -> str:
    return text if len(text) <= limit else text[:max(limit - 1, 0)] + "…"


def _short(v, budget: int, depth: int) -> str:
    if v is None or isinstance(v, bool):
        return repr(v)
    if isinstance(v, int):
        return _cut(repr(v), budget) if v.bit_length() <= 256 else f"<int of {thousands(v.bit_length())} bits>"
    if isinstance(v, float):
        return _cut(repr(v), budget)
    if isinstance(v, str):
        return _cut(repr(v), budget) if len(v) <= budget else repr(v[:budget])[:max(budget - 1, 1)] + "…"
    if isinstance(v, (bytes, bytearray)):
        return _cut(repr(bytes(v[:budget])), budget)
    if isinstance(v, (list, tuple, dict, set, frozenset)):
        opening, closing = ("{", "}") if isinstance(v, (dict, set, frozenset)) else ("[", "]")
        if depth >= 3 or budget < 6:
            return f"{opening}…{closing}" if len(v) else opening + closing
        parts, used = [], 2
        items = v.items() if isinstance(v, dict) else v
        for item in items:
            room = budget - used - 5                       # keep room for ", …]"
            if room < 3:
                parts.append("…")
                break
            if isinstance(v, dict):
                k = _short(item[0], max(room // 2, 3), depth + 1)
                s = f"{k}: {_short(item[1], max(room - len(k) - 2, 3), depth + 1)}"
            else:
                s = _short(item, room, depth + 1)
            parts.append(s)
            used += len(s) + 2
        return _cut(opening + ", ".join(parts) + closing, budget)
    return f"<{type(v).__name__}>"


def name_list(names, limit: int = NAME_LIST_ITEMS) -> str:
    """``['a', 'b', … and 199 990 more]``: at most ``limit`` names (each excerpted), then the count."""
    names = names if isinstance(names, (list, tuple)) else list(names)
    shown = ", ".join(excerpt(n, 40) for n in names[:limit])
    rest = len(names) - limit
    return f"[{shown}, … and {thousands(rest)} more]" if rest > 0 else f"[{shown}]"


def near_names(name, known, n: int = 1) -> list[str]:
    """Up to ``n`` of ``known`` close to ``name`` (a typo's likely intent, by difflib's ratio;
    ``name`` cut to 100 characters so a huge one costs nothing), best first."""
    import difflib

    return difflib.get_close_matches(str(name)[:100], sorted(known), n=n)


# -- output paths, checked before the work that writes them -------------------------------------

def path_excerpt(path: Path) -> str:
    """A path as an error message quotes it: at most ``EXCERPT_CHARS`` characters."""
    text = str(path)
    return text if len(text) <= EXCERPT_CHARS else text[:EXCERPT_CHARS - 1] + "…"


def writable_file(path, flag: str, inputs=()) -> Path:
    """``path`` (a file a command will write, e.g. ``--json``) once a file can be written there —
    its directory created, an existing file left as it is — or :class:`FlexmbError` naming
    ``flag``; also when it is one of the command's ``inputs`` (paths it reads: a scene, a bag;
    None where an optional input was not given), which writing would destroy. Called before the
    run, so that no work is lost to a bad output path."""
    p = Path(path)
    try:
        if p.is_dir():
            raise FlexmbError(f"{flag} {path_excerpt(p)}: is a directory (expected the path of a file to write)")
        existed = p.exists()
        if existed and any(i and Path(i).exists() and p.samefile(i) for i in inputs):
            raise FlexmbError(f"{flag} {path_excerpt(p)}: is an input of this command; expected another path "
                              "(writing there would overwrite it)")
        p.parent.mkdir(parents=True, exist_ok=True)
        with open(p, "a"):
            pass
    except OSError as exc:          # also from is_dir()/exists(): a name too long, a loop of links
        raise FlexmbError(f"{flag} {path_excerpt(p)}: cannot write there ({exc.strerror or exc})") from None
    if not existed:
        p.unlink()
    return p


def writable_dir(path, flag: str) -> Path:
    """``path`` (a directory a command will write into, e.g. ``--out``), created if missing, or
    :class:`FlexmbError` naming ``flag``."""
    p = Path(path)
    try:
        if p.exists() and not p.is_dir():
            raise FlexmbError(f"{flag} {path_excerpt(p)}: exists and is not a directory")
        p.mkdir(parents=True, exist_ok=True)
        probe = p / f".flexmb-write-probe-{os.getpid()}"
        probe.touch()
        probe.unlink()
    except OSError as exc:          # also from exists(): a name too long, a loop of links
        raise FlexmbError(f"{flag} {path_excerpt(p)}: cannot write there ({exc.strerror or exc})") from None
    return p
