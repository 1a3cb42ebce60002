"""The settings schema: frozen dataclass sections whose fields say what they are.

A field made by :func:`setting` carries its default, unit, doc, bounds and TOML key in its
``metadata``; a field made by :func:`section` holds a nested section (a TOML table). From
that one declaration this module derives, for any section:

* reading (:func:`from_table`): a TOML table to a section, refusing unknown keys, wrong
  types and out-of-range values with a message naming the place (file, table) and the key;
* validation (:func:`validate`, called by every section's ``__post_init__``): the same
  type and bound checks for sections built in code;
* writing (:func:`to_toml`): the TOML text that :func:`from_table` reads back to an equal
  section;
* command-line flags (:func:`add_arguments`, :func:`section_from_args`);
* runtime parameters (:func:`parameters`): name, unit, bounds, read-only reason.

Supported field types: ``float``, ``int``, ``bool``, ``str``, ``tuple[str, ...]``,
``tuple[float, float, ...]`` (fixed length), ``X | None`` of these (None: absent from the
file), nested sections (:func:`section`; optional ones are None unless their table is in the
file, and have no command-line flags) and arrays of them (:func:`tables`). Errors are
:class:`ConfigError`, formatted
``<place>: <Section>.<key>: <problem>`` (the place: a file and its table).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import types
import typing
from dataclasses import MISSING, dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, TypeVar

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

T = TypeVar("T")


class ConfigError(ValueError):
    """A configuration value is missing, of the wrong type or out of range."""


def setting(default: Any = MISSING, *, doc: str, unit: str = "", lo: float | None = None,
            hi: float | None = None, open_lo: bool = False, key: str | None = None,
            choices: tuple[str, ...] | None = None, param: str | None = None,
            read_only: str | None = None) -> Any:
    """A field with its ``default`` (MISSING: required), ``unit``, ``doc`` and bounds.

    Numbers must satisfy ``lo < x`` (``open_lo``) or ``lo <= x``, and ``x <= hi``; strings
    must be one of ``choices`` when given. ``key`` is the TOML key (default: the field's
    name); ``param`` the runtime parameter's short name (default: the key in capitals);
    ``read_only`` why the field cannot change at runtime.
    """
    meta = {"doc": doc, "unit": unit, "lo": lo, "hi": hi, "open_lo": open_lo, "key": key,
            "choices": choices, "param": param, "read_only": read_only}
    return dataclasses.field(default=default, metadata=meta)


def section(cls: Callable[[], Any], doc: str, key: str | None = None,
            optional: bool = False) -> Any:
    """A field holding a nested section (a TOML table), by default ``cls()``; ``optional``
    (annotation ``Section | None``): None unless the file has the table."""
    meta = {"doc": doc, "key": key, "section": True}
    if optional:
        return dataclasses.field(default=None, metadata=meta)
    return dataclasses.field(default_factory=cls, metadata=meta)


def tables(doc: str, key: str | None = None) -> Any:
    """A field holding a tuple of sections (a TOML array of tables), by default empty; its
    annotation is ``tuple[Section, ...]``."""
    return dataclasses.field(default=(), metadata={"doc": doc, "key": key, "tables": True})


@dataclass(frozen=True)
class FieldInfo:
    """A field of a section with its resolved type."""

    name: str                  # attribute name
    key: str                   # TOML key
    type: Any                  # the annotation without ``| None``
    optional: bool             # ``X | None``
    default: Any               # MISSING when required
    meta: Mapping[str, Any]

    @property
    def is_section(self) -> bool:
        return bool(self.meta.get("section"))

    @property
    def is_tables(self) -> bool:
        return bool(self.meta.get("tables"))

    @property
    def unit(self) -> str:
        return str(self.meta.get("unit") or "")

    @property
    def doc(self) -> str:
        return str(self.meta.get("doc") or "")


_FIELDS: dict[type, tuple[FieldInfo, ...]] = {}


def fields(cls: type) -> tuple[FieldInfo, ...]:
    """The fields of section ``cls``, in declaration order (resolved once per class)."""
    got = _FIELDS.get(cls)
    if got is None:
        got = _FIELDS[cls] = _resolve(cls)
    return got


def _resolve(cls: type) -> tuple[FieldInfo, ...]:
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        tp, optional = hints[f.name], False
        if isinstance(tp, types.UnionType) or typing.get_origin(tp) is typing.Union:
            args = [a for a in typing.get_args(tp) if a is not type(None)]
            tp, optional = args[0], len(args) < len(typing.get_args(tp))
        default = (f.default if f.default is not MISSING else
                   f.default_factory() if f.default_factory is not MISSING else MISSING)
        out.append(FieldInfo(f.name, f.metadata.get("key") or f.name, tp, optional, default,
                             f.metadata))
    return tuple(out)


# --- values -----------------------------------------------------------------------------
def _show(value: Any) -> str:
    """``value`` as messages show it: sequences as TOML lists."""
    return repr(list(value)) if isinstance(value, tuple) else repr(value)


def _number_problem(value: Any) -> str | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"expected a number, got {_show(value)}"
    if not math.isfinite(value):
        return f"must be finite, got {_show(value)}"
    return None


def _bounds_problem(f: FieldInfo, value: float) -> str | None:
    lo, hi, unit = f.meta.get("lo"), f.meta.get("hi"), f" [{f.unit}]" if f.unit else ""
    if lo is not None and (value < lo or (f.meta.get("open_lo") and value == lo)):
        rel = ">" if f.meta.get("open_lo") else ">="
        return f"must be {rel} {lo:g}{unit}, got {_show(value)}"
    if hi is not None and value > hi:
        return f"must be <= {hi:g}{unit}, got {_show(value)}"
    return None


def _problem(f: FieldInfo, value: Any) -> str | None:
    """Why ``value`` does not fit field ``f`` (Python values: tuples, not lists), or None."""
    if value is None:
        return None if f.optional else "missing"
    tp = f.type
    if tp is bool:
        return None if isinstance(value, bool) else f"expected true or false, got {_show(value)}"
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            return f"expected an integer, got {_show(value)}"
        return _bounds_problem(f, value)
    if tp is float:
        return _number_problem(value) or _bounds_problem(f, value)
    if tp is str:
        if not isinstance(value, str) or not value:
            return f"expected a non-empty string, got {_show(value)}"
        choices = f.meta.get("choices")
        if choices and value not in choices:
            return f"expected {' or '.join(choices)}, got {_show(value)}"
        return None
    if typing.get_origin(tp) is tuple:
        args = typing.get_args(tp)
        if f.is_tables:
            if not isinstance(value, tuple) or not all(isinstance(x, args[0]) for x in value):
                return f"expected a list of {args[0].__name__}, got {_show(value)}"
            return None
        if len(args) == 2 and args[1] is Ellipsis:
            if not isinstance(value, tuple) or not all(isinstance(x, str) and x
                                                       for x in value):
                return f"expected a list of strings, got {_show(value)}"
            return None
        if not isinstance(value, tuple) or len(value) != len(args) or any(
                _number_problem(x) for x in value):
            return f"expected a list of {len(args)} finite numbers, got {_show(value)}"
        return None
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return None if isinstance(value, tp) else f"expected a {tp.__name__}, got {_show(value)}"
    raise TypeError(f"field {f.name}: unsupported type {tp!r}")


def validate(obj: Any) -> None:
    """Check every field of section ``obj`` against its type and bounds (for
    ``__post_init__``); raises :class:`ConfigError` ``<Section>.<key>: <problem>``."""
    for f in fields(type(obj)):
        problem = _problem(f, getattr(obj, f.name))
        if problem is not None:
            raise ConfigError(f"{type(obj).__name__}.{f.key}: {problem}")


def _from_toml(f: FieldInfo, value: Any) -> Any:
    """A TOML value as the Python value of field ``f`` (lists to tuples, ints to floats)."""
    if isinstance(value, list):
        value = tuple(value)
    if f.type is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if isinstance(value, tuple) and typing.get_origin(f.type) is tuple \
            and typing.get_args(f.type)[-1] is float:
        return tuple(float(x) if isinstance(x, int) and not isinstance(x, bool) else x
                     for x in value)
    return value


# --- reading ----------------------------------------------------------------------------
def load_toml(path: Path, what: str, error: type[ValueError] = ConfigError) -> dict[str, Any]:
    """Read a TOML file; unreadable or invalid files raise ``error`` naming the path."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise error(f"{path}: cannot read {what}: {exc.strerror}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML: {exc}") from None


def _place(where: str, key: str) -> str:
    """The place of a nested table: ``robot.toml`` + ``can`` -> ``robot.toml [can]``."""
    if where.endswith("]"):
        return f"{where[:-1]}.{key}]"
    return f"{where} [{key}]"


def from_table(cls: type[T], table: Mapping[str, Any], where: str) -> T:
    """Build section ``cls`` from a TOML table; ``where`` names the place for messages
    (e.g. ``"scenarios/paper.toml [control]"``). Unknown keys, wrong types, out-of-range
    values and missing required fields raise :class:`ConfigError`."""
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where}: expected a table, got {table!r}")
    infos = fields(cls)
    keys = {f.key for f in infos}
    unknown = sorted(set(table) - keys)
    if unknown:
        raise ConfigError(f"{where}: unknown field(s) {', '.join(unknown)}; "
                          f"allowed: {', '.join(sorted(keys))}")
    values: dict[str, Any] = {}
    for f in infos:
        if f.is_section:
            if f.key in table or not f.optional:
                values[f.name] = from_table(f.type, table.get(f.key, {}), _place(where, f.key))
        elif f.is_tables and f.key in table:
            values[f.name] = _tables_from_toml(f, table[f.key], where)
        elif f.key in table:
            value = _from_toml(f, table[f.key])
            problem = _problem(f, value)
            if problem is not None:
                raise ConfigError(f"{where}: {cls.__name__}.{f.key}: {problem}")
            values[f.name] = value
        elif f.default is MISSING:
            raise ConfigError(f"{where}: {cls.__name__}.{f.key}: missing")
    try:
        return cls(**values)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None


def _tables_from_toml(f: FieldInfo, value: Any, where: str) -> tuple:
    """An array of tables as a tuple of the sections of field ``f``."""
    if not isinstance(value, list) or not all(isinstance(x, Mapping) for x in value):
        raise ConfigError(f"{where}: {f.key}: expected an array of tables [[...{f.key}]], "
                          f"got {value!r}")
    cls = typing.get_args(f.type)[0]
    return tuple(from_table(cls, x, f"{_place(where, f.key)}[{i}]") for i, x in enumerate(value))


class TableReader:
    """Typed access to the values of hand-read TOML files (scenarios, manifests), with
    messages ``<where>: <field>: <problem>``; settings sections use :func:`from_table`."""

    def __init__(self, where: str, error: type[ValueError] = ConfigError):
        self.where, self.error = where, error

    def fail(self, field: str, msg: str) -> ValueError:
        return self.error(f"{self.where}: {field}: {msg}")

    def string(self, table: Mapping[str, Any], key: str, field: str,
               default: str | None = None) -> str:
        value = table.get(key, default)
        if not isinstance(value, str) or not value:
            raise self.fail(field, "missing" if value is None
                            else f"expected a non-empty string, got {value!r}")
        return value

    def integer(self, table: Mapping[str, Any], key: str, field: str, default: int | None = None,
                lo: int | None = None, hi: int | None = None) -> int:
        value = table.get(key, default)
        if value is None:
            raise self.fail(field, "missing")
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(field, f"expected an integer, got {value!r}")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise self.fail(field, f"must be in [{lo}, {hi}], got {value}")
        return value

    def number(self, table: Mapping[str, Any], key: str, field: str,
               default: float | None = None, positive: bool = False) -> float:
        if key not in table:
            if default is None:
                raise self.fail(field, "missing")
            return default
        value = table[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value):
            raise self.fail(field, f"expected a finite number, got {value!r}")
        if positive and value <= 0:
            raise self.fail(field, f"must be > 0, got {value!r}")
        return float(value)

    def vector(self, table: Mapping[str, Any], key: str, field: str, size: int,
               default: tuple[float, ...] | None = None) -> tuple[float, ...]:
        if key not in table:
            if default is None:
                raise self.fail(field, "missing")
            return default
        value = table[key]
        if not isinstance(value, list) or len(value) != size or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                for x in value):
            raise self.fail(field, f"expected a list of {size} finite numbers, got {value!r}")
        return tuple(float(x) for x in value)

    def vector2(self, table: Mapping[str, Any], key: str, field: str,
                default: tuple[float, float] | None = None) -> tuple[float, float]:
        """:meth:`vector` of size 2, typed as a pair."""
        x, y = self.vector(table, key, field, 2, default)
        return x, y

    def table(self, doc: Mapping[str, Any], key: str) -> dict[str, Any]:
        value = doc.get(key, {})
        if not isinstance(value, dict):
            raise self.fail(f"[{key}]", f"expected a table, got {value!r}")
        return value

    def array_of_tables(self, doc: Mapping[str, Any], key: str,
                        required: bool) -> list[dict[str, Any]]:
        value = doc.get(key, [])
        if not isinstance(value, list) or not all(isinstance(x, dict) for x in value):
            raise self.fail(f"[[{key}]]", "expected an array of tables")
        if required and not value:
            raise self.fail(f"[[{key}]]", "missing: at least one entry is required")
        return value

    def only(self, table: Mapping[str, Any], allowed: set[str], field: str) -> None:
        unknown = sorted(set(table) - allowed)
        if unknown:
            raise self.fail(field, f"unknown field(s) {', '.join(unknown)}; "
                                   f"allowed: {', '.join(sorted(allowed))}")


# --- writing ----------------------------------------------------------------------------
def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, int):
        return str(value)
    raise TypeError(f"no TOML form for {value!r}")


def to_toml(obj: Any, table: str = "") -> str:
    """The TOML text of section ``obj`` (what :func:`from_table` reads back to an equal
    section); None values are left out, nested sections become tables."""
    lines = [f"{f.key} = {_toml_value(getattr(obj, f.name))}" for f in fields(type(obj))
             if not (f.is_section or f.is_tables) and getattr(obj, f.name) is not None]
    if table and lines:
        lines.insert(0, f"[{table}]")
    text = "\n".join(lines)
    for f in fields(type(obj)):
        name = f"{table}.{f.key}" if table else f.key
        value = getattr(obj, f.name)
        subs = ([to_toml(value, name)] if f.is_section and value is not None else
                [f"[[{name}]]\n" + to_toml(x) for x in value] if f.is_tables else [])
        for sub in subs:
            if sub:
                text += ("\n\n" if text else "") + sub.rstrip("\n")
    return text + "\n" if text else ""


# --- command-line flags -----------------------------------------------------------------
def _dest(prefix: str, f: FieldInfo) -> str:
    return (prefix + f.key).replace("-", "_")


def add_arguments(parser: argparse.ArgumentParser | argparse._ArgumentGroup, cls: type,
                  prefix: str = "") -> None:
    """Add one ``--<prefix><key>`` flag per field of ``cls`` (nested sections as
    ``--<prefix><section>-<key>``), with the field's type, default and a help text that
    gives the unit and default; read them back with :func:`section_from_args`."""
    for f in fields(cls):
        if f.is_tables or (f.is_section and f.optional):     # no flags: files only
            continue
        if f.is_section:
            add_arguments(parser, f.type, f"{prefix}{f.key}-")
            continue
        flag = "--" + (prefix + f.key).replace("_", "-")
        unit = f" [{f.unit}]" if f.unit else ""
        kwargs: dict[str, Any] = {"dest": _dest(prefix, f)}
        if f.default is MISSING:
            kwargs["required"] = True
            kwargs["help"] = f"{f.doc}{unit} (required)"
        else:
            kwargs["default"] = f.default
            kwargs["help"] = f"{f.doc}{unit} (default: %(default)s)"
        if f.type is bool:
            kwargs["action"] = argparse.BooleanOptionalAction
        elif typing.get_origin(f.type) is tuple:
            args = typing.get_args(f.type)
            many = len(args) == 2 and args[1] is Ellipsis
            kwargs.update(nargs="*" if many else len(args), type=args[0],
                          metavar=f.key.upper())
        else:
            kwargs["type"] = f.type
            if f.meta.get("choices"):
                kwargs["choices"] = f.meta["choices"]
        parser.add_argument(flag, **kwargs)


def add_argument_for(parser: argparse.ArgumentParser | argparse._ArgumentGroup, flag: str,
                     cls: type, name: str) -> None:
    """Add ``flag`` for field ``name`` of section ``cls``: its type, default, unit and doc
    (for commands whose flags keep their own names; bounds are checked when the section is
    built from the value)."""
    f = next((f for f in fields(cls) if f.name == name), None)
    if f is None or f.is_section:
        raise ValueError(f"{cls.__name__} has no setting {name!r}")
    unit = f" [{f.unit}]" if f.unit else ""
    parser.add_argument(flag, type=f.type, default=f.default,
                        help=f"{f.doc}{unit} (default: %(default)s)")


def section_from_args(cls: type[T], args: argparse.Namespace, prefix: str = "") -> T:
    """Section ``cls`` from the flags :func:`add_arguments` added (validated: a bad value
    raises :class:`ConfigError` naming the flag)."""
    values: dict[str, Any] = {}
    for f in fields(cls):
        if f.is_tables or (f.is_section and f.optional):
            continue
        if f.is_section:
            values[f.name] = section_from_args(f.type, args, f"{prefix}{f.key}-")
            continue
        value = getattr(args, _dest(prefix, f))
        values[f.name] = tuple(value) if isinstance(value, list) else value
        problem = _problem(f, values[f.name])
        if problem is not None:
            raise ConfigError(f"--{(prefix + f.key).replace('_', '-')}: {problem}")
    flags = "--" + prefix.replace("_", "-").rstrip("-") if prefix else "flags"
    try:
        return cls(**values)
    except ConfigError as exc:
        raise ConfigError(f"{flags}: {exc}") from None


# --- runtime parameters -----------------------------------------------------------------
@dataclass(frozen=True)
class Param:
    """A numeric field of a section as a runtime parameter."""

    index: int
    name: str                  # prefix + short name, e.g. BS_K_THETA
    field: str                 # attribute of the section
    unit: str
    doc: str
    lo: float | None
    hi: float | None
    read_only: str | None      # why it cannot be set at runtime, or None


def parameters(cls: type, prefix: str) -> tuple[Param, ...]:
    """The numeric fields of section ``cls`` as parameters, in field order, named
    ``prefix`` + the field's ``param`` short name (default: its key in capitals)."""
    out: list[Param] = []
    for f in fields(cls):
        if f.is_section or f.type not in (float, int):
            continue
        name = prefix + (f.meta.get("param") or f.key.upper())
        out.append(Param(len(out), name, f.name, f.unit, f.doc, f.meta.get("lo"),
                         f.meta.get("hi"), f.meta.get("read_only")))
    return tuple(out)
