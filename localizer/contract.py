"""Contracts: each input skyfix reads is one typed definition, and a bad value is one line.

A contract (the calibration tables, ``skyfix run``'s options, a scenario) is a frozen
pydantic dataclass: the class is the validation, the defaults and the documentation of
every key, and its JSON Schema is generated from it (``groundstation/schemas/``).
Validation happens once, at load; afterwards the objects are plain frozen dataclasses
whose attributes the computation reads directly. The Zenoh messages skyfix writes are
pydantic models in :mod:`groundstation.messages`.

:func:`validate` turns the first problem pydantic finds into a :class:`ConfigError`
naming the file, the key (``table.key``, ``key[i]`` for list items, ``[table]`` for a
whole table) and the offending value, with a short reason. Validators that check more
than one value raise :class:`Invalid` to name the key themselves.
"""

from __future__ import annotations

import dataclasses
from typing import Annotated, Any, get_args, get_origin

from annotated_types import Ge, Gt, Le, Len
from pydantic import AllowInfNan, ConfigDict, Strict, TypeAdapter, ValidationError


class ConfigError(ValueError):
    """A bad calibration, option or scenario value; the message is one line naming file, key and value."""

    def __init__(self, source: str, key: str, value, why: str):
        self.source, self.key, self.value, self.why = source, key, value, why
        super().__init__(f"{source}: {key} = {value!r}: {why}")


class Invalid(ValueError):
    """Raised by a contract's own validator: ``key`` relative to the validated object (dotted)."""

    def __init__(self, key: str, value, why: str):
        self.key, self.value, self.why = key, value, why
        super().__init__(why)


# Value types: TOML numbers as they are (an int is a float too, a bool or a string is neither),
# finite; whole numbers stay whole; fixed-length lists become tuples.
Number = Annotated[float, Strict(), AllowInfNan(False)]
Positive = Annotated[Number, Gt(0)]
NonNegative = Annotated[Number, Ge(0)]
Whole = Annotated[int, Strict()]
Flag = Annotated[bool, Strict()]
Text = Annotated[str, Strict()]
Vector3 = Annotated[tuple[Number, ...], Len(3, 3)]
Vector4 = Annotated[tuple[Number, ...], Len(4, 4)]
Vector5 = Annotated[tuple[Number, ...], Len(5, 5)]
Pair = Annotated[tuple[Number, ...], Len(2, 2)]


def within(lo: float, hi: float):
    """Metadata for a number in ``[lo, hi]``."""
    return Annotated[Number, Ge(lo), Le(hi)]


#: Settings of a contract table: unknown keys refused.
CLOSED = ConfigDict(extra="forbid")
#: Tables of the session format v1, where other tools may add keys (skyfix warns about them).
OPEN = ConfigDict(extra="ignore")

_ADAPTERS: dict[type, TypeAdapter] = {}


def adapter(cls) -> TypeAdapter:
    """The (cached) pydantic TypeAdapter of a contract class."""
    if cls not in _ADAPTERS:
        _ADAPTERS[cls] = TypeAdapter(cls)
    return _ADAPTERS[cls]


def validate(cls, data: Any, source: str, prefix: str = ""):
    """``data`` (parsed TOML) as a ``cls``, or :class:`ConfigError` for the first problem.

    ``prefix`` is prepended to keys (``"camera"`` when validating one table).
    """
    try:
        return adapter(cls).validate_python(data)
    except ValidationError as e:
        errors = e.errors()
        # a wrong or misspelt key first: it often explains a missing one
        first = next((err for err in errors if err["type"] != "missing"), errors[0])
        raise error_of(cls, first, source, prefix) from None


def _join(parts) -> str:
    key = ""
    for p in parts:
        key += f"[{p}]" if isinstance(p, int) else (f".{p}" if key else str(p))
    return key


def _field_class(cls, loc) -> type | None:
    """The contract class at ``loc`` below ``cls`` (None when it is not a table)."""
    for name in loc:
        if not dataclasses.is_dataclass(cls) or isinstance(name, int):
            return None
        by_alias = {_alias(cls, f.name): f for f in dataclasses.fields(cls)}
        f = by_alias.get(name)
        if f is None:
            return None
        cls = _table_type(_field_type(cls, f.name))
    return cls


def _alias(cls, name: str) -> str:
    info = getattr(cls, "__pydantic_fields__", {}).get(name)
    return (info.alias or name) if info is not None else name


def _field_type(cls, name: str):
    """The resolved annotation of field ``name`` of a pydantic dataclass."""
    return cls.__pydantic_fields__[name].annotation


def _table_type(tp):
    """The dataclass inside ``tp`` (``X``, ``X | None``, ``Annotated[X, ...]``), or None."""
    if dataclasses.is_dataclass(tp):
        return tp
    if get_origin(tp) is Annotated:
        return _table_type(get_args(tp)[0])
    for arg in get_args(tp):
        found = _table_type(arg)
        if found is not None:
            return found
    return None


def known_keys(cls) -> list[str]:
    """The keys a contract table accepts, as written in the file (aliases)."""
    return [_alias(cls, f.name) for f in dataclasses.fields(cls) if f.init]


_WHY = {
    "float_type": "expected a number",
    "int_type": "expected a whole number",
    "string_type": "expected a string",
    "bool_type": "expected true or false",
    "tuple_type": "expected a list",
    "finite_number": "must be finite",
    "missing": "missing",
    "string_too_short": "must not be empty",
}


def _why(err: dict, table) -> str:
    kind, ctx = err["type"], err.get("ctx") or {}
    if kind in _WHY:
        return _WHY[kind]
    if kind in ("extra_forbidden", "unexpected_keyword_argument"):
        return (
            f"unknown key (known: {', '.join(sorted(known_keys(table)))})"
            if table
            else "unknown key"
        )
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        op = {
            "greater_than": ">",
            "greater_than_equal": "≥",
            "less_than": "<",
            "less_than_equal": "≤",
        }[kind]
        bound = next(iter(ctx.values()))
        return (
            f"must be {op} {bound:g}"
            if isinstance(bound, (int, float))
            else f"must be {op} {bound}"
        )
    if kind == "literal_error":
        return f"expected one of {ctx['expected']}"
    if kind in ("too_short", "too_long"):
        return f"expected a list of {ctx.get('min_length', ctx.get('max_length'))} values"
    if kind in ("dataclass_type", "model_type", "dict_type"):
        return "expected a table"
    return err["msg"].removeprefix("Value error, ").replace("Input should be", "expected")


def error_of(cls, err: dict, source: str, prefix: str = "") -> ConfigError:
    """One pydantic error record as a :class:`ConfigError`."""
    loc = tuple(err["loc"])
    value = err["input"]
    exc = (err.get("ctx") or {}).get("error")
    if isinstance(exc, Invalid):
        key = _join(
            (*((prefix,) if prefix else ()), *loc, *(exc.key.split(".") if exc.key else ()))
        )
        return ConfigError(source, key, exc.value, exc.why)
    parts = (*((prefix,) if prefix else ()), *loc)
    key = _join(parts) or "(top level)"
    if err["type"] == "missing":
        value = None
    whole_table = _field_class(cls, loc) is not None and err["type"] in (
        "missing",
        "dataclass_type",
        "dict_type",
    )
    if whole_table:
        key = f"[{key}]"
    table = _field_class(cls, loc[:-1]) if loc else cls
    if err["type"] in ("extra_forbidden", "unexpected_keyword_argument") and table is None:
        table = cls if len(loc) == 1 else None
    return ConfigError(source, key, value, _why(err, table))


def unknown_keys(cls, data: Any, prefix: str = "") -> list[str]:
    """Keys of ``data`` that open tables (``extra="ignore"``) of ``cls`` do not know, as ``table.key``."""
    if not isinstance(data, dict) or not dataclasses.is_dataclass(cls):
        return []
    config = getattr(cls, "__pydantic_config__", {})
    known = {_alias(cls, f.name): f for f in dataclasses.fields(cls) if f.init}
    out = []
    for key, value in data.items():
        full = f"{prefix}.{key}" if prefix else key
        if key not in known:
            if config.get("extra") == "ignore":
                out.append(full)
            continue
        sub = _table_type(_field_type(cls, known[key].name))
        if sub is not None:
            out += unknown_keys(sub, value, full)
    return out
