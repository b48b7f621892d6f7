"""The config file spawned agents read when a run changes the config (as ``vr-sim run``).

An agent finds its cameras and channels under its own ``[[agent]]`` in the config file
(``vrsync.Agent.connect`` refuses an id the file does not list). When ``--spawn-agents``
resizes the agent list, ``--session`` renames the session, or the host bound a TCP port of
its own choosing, the agents need a file that says so: :func:`agents_config_text` makes its
text from the original file, and :func:`dumps` writes TOML (the standard library only
reads it).
"""

from __future__ import annotations

import copy
import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ["agents_config_text", "dumps"]

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")
# Keys of an [[agent]] that added agents do not copy (the bridge's with_agent_count gives
# them the config's defaults).
_NOT_COPIED = ("id", "transport", "wait_for_stop")


def agents_config_text(
    path: str | Path,
    *,
    agents: int | None = None,
    session: str | None = None,
    tcp_listen: str | None = None,
) -> str:
    """The text of ``path`` with the agent list resized to ids ``0..agents`` (added
    agents copy the last ``[[agent]]``'s cameras and channels), the session renamed
    and ``[transport] tcp_listen`` set, each when given. The ``[world]`` table is left
    out: agents do not read it, and its relative paths would not hold elsewhere."""
    with Path(path).open("rb") as f:
        doc: dict[str, Any] = tomllib.load(f)
    doc.pop("world", None)
    if session is not None:
        doc["session"] = session
    if tcp_listen is not None:
        doc.setdefault("transport", {})["tcp_listen"] = tcp_listen
    if agents is not None:
        listed = {int(a["id"]): a for a in doc.get("agent", [])}
        last = max(listed.items())[1] if listed else {}
        template = {k: v for k, v in last.items() if k not in _NOT_COPIED}
        doc["agent"] = [
            listed.get(i) or {"id": i, **copy.deepcopy(template)} for i in range(agents)
        ]
    return dumps(doc)


def dumps(doc: Mapping[str, Any]) -> str:
    """``doc`` (as ``tomllib`` reads it: tables, arrays of tables, strings, numbers,
    booleans, arrays) as TOML text that reads back equal."""
    lines: list[str] = []
    _table(lines, [], doc)
    return "\n".join(lines).lstrip("\n") + "\n"


def _table(lines: list[str], path: list[str], table: Mapping[str, Any]) -> None:
    for k, v in table.items():
        if not isinstance(v, dict) and not _array_of_tables(v):
            lines.append(f"{_key(k)} = {_value(v)}")
    for k, v in table.items():
        if isinstance(v, dict):
            lines.append(f"\n[{_dotted([*path, k])}]")
            _table(lines, [*path, k], v)
        elif _array_of_tables(v):
            for item in v:
                lines.append(f"\n[[{_dotted([*path, k])}]]")
                _table(lines, [*path, k], item)


def _array_of_tables(v: object) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def _dotted(path: Sequence[str]) -> str:
    return ".".join(_key(k) for k in path)


def _key(k: str) -> str:
    return k if _BARE_KEY.match(k) else _string(k)


def _string(s: str) -> str:
    out = ['"']
    for ch in s:
        if ch in ('"', "\\"):
            out.append("\\" + ch)
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    out.append('"')
    return "".join(out)


def _value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} as TOML: {v!r}")
