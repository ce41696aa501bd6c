"""Nested frozen-dataclass configs from TOML files with ``key.sub=value`` overrides.

Any frozen dataclass whose fields are bool / int / float / str, ``X | None``, ``tuple[X, ...]``,
``tuple[X, Y]``, ``Literal[...]``, ``dict[str, X]`` or another such dataclass can be loaded::

    cfg = load_config(MyConfig, "experiments/stage1.toml", ["ppo.learning_rate=3e-4",
                                                           "train.experiment=stage1b"])

Override values are parsed as TOML literals (``1e-3``, ``true``, ``[8, 16]``, ``"text"``); a
value that is not valid TOML is taken as a bare string (``train.experiment=stage1``). ``none``
sets an optional field to None. An unknown key or a value of the wrong type raises ConfigError
naming the full key path and the expected type. Field docs live in
``field(metadata={"help": ...})``.
"""

from __future__ import annotations

import dataclasses
import json
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Iterable, Mapping


class ConfigError(ValueError):
    """A config file or override does not fit the config dataclasses."""


# ----------------------------------------------------------------------------- typing helpers


def _type_name(tp: Any) -> str:
    if isinstance(tp, type):
        return tp.__name__
    return str(tp).replace("typing.", "")


def _is_optional(tp: Any) -> tuple[bool, Any]:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(tp)) == 2:
            return True, args[0]
    return False, tp


def _convert(value: Any, tp: Any, key: str) -> Any:
    """Check ``value`` against the annotation ``tp`` and convert it (lists -> tuples, dicts ->
    dataclasses, int -> float).

    Long: one branch per supported annotation, read as a table.
    """

    def fail(extra: str = "") -> ConfigError:
        got = f"{type(value).__name__} {value!r}"
        return ConfigError(f"config key '{key}': expected {_type_name(tp)}, got {got}{extra}")

    optional, inner = _is_optional(tp)
    if optional:
        if value is None or (isinstance(value, str) and value.lower() in ("none", "null")):
            return None
        return _convert(value, inner, key)
    if tp is Any:
        return value
    if dataclasses.is_dataclass(tp):
        if dataclasses.is_dataclass(value) and isinstance(value, tp):
            return value
        if not isinstance(value, Mapping):
            raise fail(" (a table)")
        return from_dict(tp, value, prefix=key)
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin is typing.Literal:
        if value not in args:
            raise ConfigError(f"config key '{key}': expected one of {list(args)}, got {value!r}")
        return value
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise fail()
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f"{key}[{i}]") for i, v in enumerate(value))
        if args and len(args) != len(value):
            raise fail(f" (need {len(args)} items)")
        if not args:
            return tuple(value)
        pairs = enumerate(zip(value, args, strict=True))
        return tuple(_convert(v, a, f"{key}[{i}]") for i, (v, a) in pairs)
    if origin in (dict, Mapping) or tp is dict:
        if not isinstance(value, Mapping):
            raise fail()
        kt, vt = args if args else (str, Any)
        return {_convert(k, kt, key): _convert(v, vt, f"{key}.{k}") for k, v in value.items()}
    if origin is list or tp is list:
        raise ConfigError(f"config key '{key}': use tuple[...] not list in frozen configs")
    if tp is bool:
        if not isinstance(value, bool):
            raise fail()
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise fail()
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise fail()
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise fail()
        return value
    raise ConfigError(f"config key '{key}': unsupported field type {_type_name(tp)}")


def _hints(cls: type) -> dict[str, Any]:
    try:
        return typing.get_type_hints(cls)
    except Exception as e:  # pragma: no cover - a broken annotation is a programming error
        raise ConfigError(f"cannot resolve type hints of {cls.__name__}: {e}") from e


# ----------------------------------------------------------------------------- public API


def from_dict(cls: type, data: Mapping[str, Any], prefix: str = "") -> Any:
    """Build dataclass ``cls`` from a nested mapping; missing keys keep their defaults."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"config key '{prefix or '<root>'}': expected a table, got {data!r}")
    hints = _hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    kwargs = {}
    for name, value in data.items():
        key = f"{prefix}.{name}" if prefix else name
        if name not in fields:
            known = ", ".join(sorted(fields))
            raise ConfigError(f"unknown config key '{key}' ({cls.__name__} has: {known})")
        tp = hints[name]
        if dataclasses.is_dataclass(tp) and isinstance(value, Mapping):
            value = _merge(to_dict(_default(fields[name])), value)
        kwargs[name] = _convert(value, tp, key)
    try:
        return cls(**kwargs)
    except TypeError as e:
        raise ConfigError(f"config '{prefix or cls.__name__}': {e}") from e


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None


def _merge(base: Any, update: Mapping[str, Any]) -> Any:
    """Deep-merge ``update`` into the plain dict ``base`` (a nested dataclass's default)."""
    if not isinstance(base, dict):
        return dict(update)
    out = dict(base)
    for k, v in update.items():
        out[k] = _merge(out[k], v) if isinstance(v, Mapping) and isinstance(out.get(k), dict) else v
    return out


def to_dict(cfg: Any) -> dict[str, Any]:
    """Nested plain dict (tuples -> lists) of a dataclass config, JSON/TOML-serialisable."""

    def plain(v: Any) -> Any:
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            return {f.name: plain(getattr(v, f.name)) for f in dataclasses.fields(v)}
        if isinstance(v, (tuple, list)):
            return [plain(x) for x in v]
        if isinstance(v, Mapping):
            return {str(k): plain(x) for k, x in v.items()}
        return v

    return plain(cfg)


def to_json(cfg: Any) -> str:
    return json.dumps(to_dict(cfg), indent=2, sort_keys=True)


def from_json(cls: type, text: str) -> Any:
    return from_dict(cls, json.loads(text))


def parse_value(text: str) -> Any:
    """A TOML literal (number, bool, array, quoted string, inline table) or else a bare string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def apply_overrides(data: dict[str, Any], overrides: Iterable[str]) -> dict[str, Any]:
    """Return a copy of nested ``data`` with each ``a.b.c=value`` override set."""
    data = json.loads(json.dumps(data))  # deep copy of plain data
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"override '{item}' is not of the form key.sub=value")
        key, text = item.split("=", 1)
        key = key.strip()
        parts = key.split(".")
        if not all(parts):
            raise ConfigError(f"override '{item}': bad key '{key}'")
        node = data
        for i, p in enumerate(parts[:-1]):
            nxt = node.setdefault(p, {})
            if not isinstance(nxt, dict):
                raise ConfigError(f"override '{item}': '{'.'.join(parts[: i + 1])}' is not a table")
            node = nxt
        node[parts[-1]] = parse_value(text.strip())
    return data


def read_toml_chain(path: str | Path, _seen: tuple[Path, ...] = ()) -> list[dict[str, Any]]:
    """The tables of a TOML file and of the files it inherits from, the first base first; a
    missing or malformed file is a one-line ConfigError.

    A top-level ``base = "other.toml"`` (relative to the file) inherits (recursively: a base may
    have a base of its own); read_toml merges the chain."""
    path = Path(path)
    try:
        with path.open("rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(f"{path}: config file not found") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: invalid TOML: {e}") from None
    base = data.pop("base", None)
    if base is None:
        return [data]
    if not isinstance(base, str):
        raise ConfigError(f"{path}: base: expected a file name, got {base!r}")
    base_path = (path.parent / base).resolve()
    if base_path in _seen or base_path == path.resolve():
        raise ConfigError(f"{path}: base: '{base}' inherits from itself")
    return [*read_toml_chain(base_path, (*_seen, path.resolve())), data]


def read_toml(path: str | Path) -> dict[str, Any]:
    """The table of a TOML file; a missing or malformed file is a one-line ConfigError.

    A top-level ``base = "other.toml"`` (relative to the file) inherits: the file's tables are
    deep-merged over the base's (recursively: a base may have a base of its own)."""
    return merge_tables(read_toml_chain(path))


def merge_tables(tables: Iterable[Mapping[str, Any]]) -> dict[str, Any]:
    """The tables deep-merged in order, each over the ones before it."""
    merged: dict[str, Any] = {}
    for table in tables:
        merged = _merge(merged, table)
    return merged


def load_config(
    cls: type, path: str | Path | None = None, overrides: Iterable[str] = ()
) -> Any:
    """Defaults of ``cls``, updated by the TOML file at ``path`` (if any), then by overrides."""
    data: dict[str, Any] = {}
    if path is not None:
        path = Path(path)
        data = read_toml(path)
    data = apply_overrides(data, overrides)
    try:
        return from_dict(cls, data)
    except ConfigError as e:
        where = f"{path}: " if path is not None else ""
        raise ConfigError(f"{where}{e}") from None
