"""One way to configure every service: dataclass defaults, then a TOML file, then ``--set``.

Each service declares one ``@dataclass`` whose ``__post_init__`` validates and raises
:class:`ConfigError` naming the field. ``load_config`` and ``replace_config`` are the only
ways a config is built from outside, so the file, the command line and the live
``<service>/config`` queryable all go through the same conversion and validation.
"""

import dataclasses
import math
import tomllib
import typing
from pathlib import Path
from typing import Any, Iterable, TypeVar

T = TypeVar("T")


class ConfigError(ValueError):
    """A bad configuration value; the message starts with the offending key."""


def _field_types(cls) -> dict[str, Any]:
    hints = typing.get_type_hints(cls)
    return {field.name: hints[field.name] for field in dataclasses.fields(cls)}


def _parse_bool(text: str) -> bool:
    lowered = text.strip().lower()
    if lowered in ("1", "true", "yes", "on"):
        return True
    if lowered in ("0", "false", "no", "off"):
        return False
    raise ValueError(f"not a boolean: {text!r}")


def _coerce(key: str, annotation: Any, value: Any) -> Any:
    """Convert ``value`` (a string from --set, or a TOML/msgpack value) to the field's type."""
    origin = typing.get_origin(annotation)
    try:
        if origin is list:
            (item_type,) = typing.get_args(annotation) or (Any,)
            if isinstance(value, str):
                text = value.strip()
                if text.startswith("["):
                    text = text[1:-1] if text.endswith("]") else text[1:]
                value = [part for part in text.split(",") if part.strip()]
            if not isinstance(value, (list, tuple)):
                raise ValueError(f"expected a list, got {type(value).__name__}")
            return [_coerce(key, item_type, item) for item in value]
        if annotation is bool:
            if isinstance(value, bool):
                return value
            if isinstance(value, str):
                return _parse_bool(value)
            raise ValueError(f"expected a boolean, got {value!r}")
        if annotation is int:
            if isinstance(value, bool):
                raise ValueError(f"expected an integer, got {value!r}")
            if isinstance(value, float) and value.is_integer():
                return int(value)
            if isinstance(value, (int, str)):
                return int(value)
            raise ValueError(f"expected an integer, got {value!r}")
        if annotation is float:
            if isinstance(value, bool):
                raise ValueError(f"expected a number, got {value!r}")
            number = float(value)
            if not math.isfinite(number):
                raise ValueError(f"must be finite, got {value!r}")
            return number
        if annotation is str:
            if not isinstance(value, str):
                raise ValueError(f"expected a string, got {value!r}")
            return value
    except (TypeError, ValueError) as error:
        raise ConfigError(f"{key}: {error}") from None
    return value


def _apply(cls: type[T], base: dict[str, Any], changes: dict[str, Any]) -> T:
    types = _field_types(cls)
    values = dict(base)
    for key, value in changes.items():
        if key not in types:
            known = ", ".join(sorted(types))
            raise ConfigError(f"{key}: unknown parameter (known: {known})")
        values[key] = _coerce(key, types[key], value)
    try:
        return cls(**values)
    except ConfigError:
        raise
    except (TypeError, ValueError) as error:
        raise ConfigError(str(error)) from None


def parse_overrides(overrides: Iterable[str]) -> dict[str, str]:
    """Turn ``["key=value", ...]`` into a dict; a missing ``=`` is a ConfigError."""
    parsed: dict[str, str] = {}
    for item in overrides:
        key, separator, value = item.partition("=")
        if not separator or not key.strip():
            raise ConfigError(f"{item}: expected KEY=VALUE")
        parsed[key.strip()] = value.strip()
    return parsed


def read_config_file(path: str | Path, section: str | None = None) -> dict[str, Any]:
    """Read a TOML file; keys at top level or under ``[section]`` (the service's name)."""
    try:
        with open(path, "rb") as handle:
            data = tomllib.load(handle)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such config file") from None
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(f"{path}: not valid TOML ({error})") from None
    if section and isinstance(data.get(section), dict):
        return dict(data[section])
    return {key: value for key, value in data.items() if not isinstance(value, dict)}


def load_config(cls: type[T], path: str | Path | None = None, overrides: Iterable[str] = (),
                section: str | None = None) -> T:
    """Defaults, then the TOML file at ``path``, then ``KEY=VALUE`` overrides; validated."""
    changes: dict[str, Any] = {}
    if path:
        changes.update(read_config_file(path, section))
    changes.update(parse_overrides(overrides))
    return _apply(cls, {}, changes)


def replace_config(config: T, changes: dict[str, Any]) -> T:
    """A new validated config with ``changes`` applied; ``config`` itself is left unchanged."""
    return _apply(type(config), dataclasses.asdict(config), changes)


def config_to_dict(config: Any) -> dict[str, Any]:
    return dataclasses.asdict(config)
