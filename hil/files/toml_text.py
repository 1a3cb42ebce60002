"""TOML text of a plain document (what ``tomllib.loads`` reads back to an equal dict).

For the documents the tools write themselves: a campaign's copy of its spec and a
generated scenario (``boundswarm campaign``). Values are strings, booleans, integers,
finite floats and lists of them (nested lists too); dicts are tables and lists of dicts
arrays of tables, at any depth. Settings sections have their own writer
(:func:`common.schema.to_toml`).
"""
from __future__ import annotations

import json
import math
import re
from typing import Any, Mapping

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def dumps(doc: Mapping[str, Any]) -> str:
    """The TOML text of ``doc``; a value TOML cannot hold raises ValueError naming its key."""
    return "\n".join(_table(doc, ())).strip("\n") + "\n"


def _key(key: str) -> str:
    return key if _BARE.match(key) else json.dumps(key, ensure_ascii=False)


def _is_tables(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


def _table(table: Mapping[str, Any], path: tuple[str, ...]) -> list[str]:
    lines = [f"{_key(k)} = {_value(v, path + (k,))}" for k, v in table.items()
             if v is not None and not isinstance(v, dict) and not _is_tables(v)]
    for k, v in table.items():
        name = ".".join(_key(p) for p in path + (k,))
        if isinstance(v, dict):
            lines += ["", f"[{name}]", *_table(v, path + (k,))]
        elif _is_tables(v):
            for item in v:
                lines += ["", f"[[{name}]]", *_table(item, path + (k,))]
    return lines


def _value(value: Any, path: tuple[str, ...]) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"{'.'.join(path)}: TOML has no {value!r}")
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(v, path) for v in value) + "]"
    raise ValueError(f"{'.'.join(path)}: no TOML form for {value!r}")
