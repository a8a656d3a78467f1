"""One way to configure every service: declared defaults, then a TOML file, then ``--set``.

Each service declares one ``@dataclass`` whose fields are declared with :func:`param`: the
default, a one-line meaning and the bounds, all next to the field. Everything else reads that
one declaration: the generic validation (:func:`check_fields`, type, bounds, choices), the
service's ``--help``, docs/parameters.md's tables (``deploy/params.py``) and the live
``<service>/config`` queryable's ``describe`` (:func:`describe_config`). String choices are a
``StrEnum`` field type, whose members compare equal to (and serialise as) plain strings.

``__post_init__`` calls :func:`check_fields` and then checks only rules between fields, raising
:class:`ConfigError` naming the field. ``load_config`` and ``replace_config`` are the only ways
a config is built from outside, so the file, the command line and the live queryable all go
through the same conversion and validation.

Example::

    @dataclass
    class ExampleConfig:
        gain: float = param(0.5, "loop gain", low=0, high=1)
        mode: Mode = param(Mode.fast, "how to run")

        def __post_init__(self):
            check_fields(self)
"""

import dataclasses
import enum
import json
import math
import textwrap
import tomllib
import typing
from pathlib import Path
from typing import Any, Callable, Iterable, TypeVar

from balltrack.common.keys import SERVICES
from balltrack.common.messages import shorten

T = TypeVar("T")

# The key under which param() stores its declaration in dataclasses.field(metadata=...).
METADATA_KEY = "balltrack.param"


class ConfigError(ValueError):
    """A bad configuration value; the message starts with the offending key."""


@dataclasses.dataclass(frozen=True)
class Param:
    """What :func:`param` declares about a field besides its default.

    ``low``/``high`` are inclusive bounds, or exclusive ones when ``low_open``/``high_open``;
    ``off`` is a value that switches the feature off and is accepted outside the bounds."""

    meaning: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    off: Any = None


def param(default: Any, meaning: str, *, low: float | None = None, high: float | None = None,
          above: float | None = None, below: float | None = None, off: Any = None) -> Any:
    """A dataclass field with its meaning and bounds: ``low``/``high`` inclusive,
    ``above``/``below`` exclusive (give one of each pair at most), ``off`` a value accepted
    outside them (e.g. 0 = no limit). Choices come from a ``StrEnum`` annotation."""
    if low is not None and above is not None or high is not None and below is not None:
        raise TypeError("param: give low or above, high or below, not both")
    declaration = Param(meaning=meaning,
                        low=above if above is not None else low,
                        high=below if below is not None else high,
                        low_open=above is not None, high_open=below is not None, off=off)
    metadata = {METADATA_KEY: declaration}
    if isinstance(default, (list, dict, set)):
        return dataclasses.field(default_factory=lambda: type(default)(default), metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def declaration(field: dataclasses.Field) -> Param | None:
    """The field's :class:`Param`, or None for a field declared without :func:`param`."""
    return field.metadata.get(METADATA_KEY)


def _field_types(cls) -> dict[str, Any]:
    hints = typing.get_type_hints(cls)
    return {field.name: hints[field.name] for field in dataclasses.fields(cls)}


def _is_choice(annotation: Any) -> bool:
    return isinstance(annotation, type) and issubclass(annotation, enum.Enum)


def choices(annotation: Any) -> tuple[str, ...] | None:
    """The allowed values of a choice field's type (a StrEnum), else None."""
    return tuple(member.value for member in annotation) if _is_choice(annotation) else None


def _number_text(value: float) -> str:
    # Short where that is exact; in full where six digits would state another bound (pi as
    # 3.14159 reads as if 3.14159 itself were refused).
    if not isinstance(value, float):
        return str(value)
    short = format(value, "g")
    return short if float(short) == value else repr(value)


def bounds_text(declared: Param | None) -> str:
    """``[0, 179]``, ``> 0``, ``<= 1``, ``0 or >= 64``...; empty without bounds."""
    if declared is None or (declared.low is None and declared.high is None):
        return ""
    low, high = declared.low, declared.high
    if low is not None and high is not None:
        text = (f"{'(' if declared.low_open else '['}{_number_text(low)}, "
                f"{_number_text(high)}{')' if declared.high_open else ']'}")
    elif low is not None:
        text = f"{'>' if declared.low_open else '>='} {_number_text(low)}"
    else:
        text = f"{'<' if declared.high_open else '<='} {_number_text(high)}"
    if declared.off is not None:
        text = f"{_number_text(declared.off)} or {text}"
    return text


def _within(value: float, declared: Param) -> bool:
    if declared.off is not None and value == declared.off:
        return True
    if declared.low is not None and (value <= declared.low if declared.low_open else value < declared.low):
        return False
    if declared.high is not None and (value >= declared.high if declared.high_open else value > declared.high):
        return False
    return True


def _checked(name: str, annotation: Any, value: Any, spelled: Callable[[Any], str] = repr) -> Any:
    """``value`` as the field's type (an int for a float field becomes a float, a string for a
    choice field its member), or a one-line ConfigError naming the field; ``spelled`` writes
    the value in it (``_toml_text`` for a config file's: true, "12")."""
    origin = typing.get_origin(annotation)
    if origin is list:
        (item_type,) = typing.get_args(annotation) or (Any,)
        if not isinstance(value, list):
            raise ConfigError(f"{name}: expected a list, got {spelled(value)}")
        return [_checked(name, item_type, item, spelled) for item in value]
    if annotation is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{name}: expected a boolean, got {spelled(value)}")
    elif annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{name}: expected an integer, got {spelled(value)}")
    elif annotation is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{name}: expected a number, got {spelled(value)}")
        value = float(value)
        if not math.isfinite(value):
            raise ConfigError(f"{name}: must be finite, got {spelled(value)}")
    elif _is_choice(annotation):
        try:
            return annotation(value)
        except ValueError:
            raise ConfigError(f"{name}: must be one of {', '.join(choices(annotation))}, "
                              f"got {spelled(value)}") from None
    elif annotation is str:
        if not isinstance(value, str):
            raise ConfigError(f"{name}: expected a string, got {spelled(value)}")
    return value


def check_fields(config: Any) -> None:
    """The checks every field's declaration implies, in field order: its type (converting an
    int to a float and a string to a choice member in place), finite numbers, bounds, choices."""
    types = _field_types(type(config))
    for field in dataclasses.fields(config):
        value = _checked(field.name, types[field.name], getattr(config, field.name))
        declared = declaration(field)
        if declared is not None and isinstance(value, (int, float)) and not isinstance(value, bool) \
                and not _within(value, declared):
            bounds = bounds_text(declared)
            wording = f"in {bounds}" if bounds[0] in "[(" else bounds
            raise ConfigError(f"{field.name}: must be {wording}, got {value!r}")
        setattr(config, field.name, value)


def _type_name(annotation: Any) -> str:
    if typing.get_origin(annotation) is list:
        (item,) = typing.get_args(annotation) or (Any,)
        return f"list[{_type_name(item)}]"
    if _is_choice(annotation):
        return "str"
    return getattr(annotation, "__name__", str(annotation))


def _plain(value: Any) -> Any:
    """A config value as TOML/msgpack/JSON hold it: choice members as their strings."""
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, list):
        return [_plain(item) for item in value]
    return value


def field_default(field: dataclasses.Field) -> Any:
    if field.default is not dataclasses.MISSING:
        return field.default
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    return None


def describe_config(cls: type) -> dict[str, dict[str, Any]]:
    """Every parameter's declaration, plain values only (for msgpack, JSON and tables):
    ``{name: {type, default, meaning, low, high, low_open, high_open, off, bounds, choices}}``;
    ``bounds`` is the readable form of the bounds, ``choices`` a list or None."""
    types = _field_types(cls)
    described = {}
    for field in dataclasses.fields(cls):
        declared = declaration(field) or Param(meaning="")
        allowed = choices(types[field.name])
        described[field.name] = {
            "type": _type_name(types[field.name]),
            "default": _plain(field_default(field)),
            "meaning": declared.meaning,
            "low": declared.low, "high": declared.high,
            "low_open": declared.low_open, "high_open": declared.high_open,
            "off": declared.off,
            "bounds": bounds_text(declared),
            "choices": list(allowed) if allowed else None,
        }
    return described


def format_value(value: Any) -> str:
    """A value as it is written in TOML: true/false, quoted strings."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    return repr(value)


def help_text(cls: type, width: int = 100) -> str:
    """The parameters for a service's ``--help`` epilog: name = default, type and bounds or
    choices, then the meaning, wrapped."""
    lines = ["parameters (--set NAME=VALUE, or NAME = VALUE in the --config TOML file):"]
    for name, described in describe_config(cls).items():
        allowed = described["bounds"]
        if described["choices"]:
            allowed = "one of " + ", ".join(described["choices"])
        lines.append(f"  {name} = {format_value(described['default'])}  "
                     f"({described['type']}{', ' + allowed if allowed else ''})")
        lines += textwrap.wrap(described["meaning"].replace("`", ""), width,
                               initial_indent="      ", subsequent_indent="      ")
    return "\n".join(lines)


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
            if isinstance(value, int):
                return value
            if isinstance(value, str):
                try:
                    return int(value)
                except ValueError:
                    pass
            raise ValueError(f"expected an integer, got {shorten(value, 40)!r}")
        if annotation is float:
            if isinstance(value, bool):
                raise ValueError(f"expected a number, got {value!r}")
            try:
                number = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"expected a number, got {shorten(value, 40)!r}") from None
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


def settings_by_service(items: Iterable[str], services: Iterable[str], among: str) -> dict[str, list[str]]:
    """``--set SERVICE.KEY=VALUE`` items, for several services at once, as ``KEY=VALUE`` lists
    per service of ``services``; a ConfigError (one line) for a malformed item or a service
    not among them (``among`` says which those are: "--services")."""
    grouped: dict[str, list[str]] = {name: [] for name in services}
    for item in items:
        target, separator, value = item.partition("=")
        service, dot, key = target.partition(".")
        if not separator or not dot or not service.strip() or not key.strip():
            raise ConfigError(f"--set {item}: expected SERVICE.KEY=VALUE, e.g. follower.max_size_thresh=0.3")
        if service.strip() not in grouped:
            raise ConfigError(f"--set {item}: {service.strip()} is not among {among}")
        grouped[service.strip()].append(f"{key.strip()}={value}")
    return grouped


def read_config_file(path: str | Path, section: str | None = None) -> dict[str, Any]:
    """Read a TOML file: its top-level keys, then those of its ``[section]`` table (the
    service's name), which win. One file may hold several services' tables; a table that is no
    service's (``[detectr]``), or a file with neither top-level keys nor the service's table,
    is a ConfigError: either would leave every parameter at its default without a word."""
    try:
        with open(path, "rb") as handle:
            data = tomllib.load(handle)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such config file") from None
    except OSError as error:  # (a folder, no permission)
        raise ConfigError(f"{path}: cannot read the config file ({error.strerror or error})") from None
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(f"{path}: not valid TOML ({error})") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not valid TOML (not UTF-8 text)") from None
    tables = {key: value for key, value in data.items() if isinstance(value, dict)}
    known = (*SERVICES, section) if section else SERVICES
    for name in tables:
        if name not in known:
            raise ConfigError(f"{path}: [{name}] is not a service's table (tables: {', '.join(SERVICES)})")
    settings = {key: value for key, value in data.items() if key not in tables}
    if section and section in tables:
        settings.update(tables[section])
    elif section and tables and not settings:
        raise ConfigError(f"{path}: no [{section}] table and no top-level keys for {section} "
                          f"(its tables: {', '.join(f'[{name}]' for name in tables)})")
    return settings


def _toml_text(value: Any) -> str:
    """A value as TOML writes it, shortened."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return shorten(json.dumps(value), 40)
    return shorten(value, 40)


def load_config(cls: type[T], path: str | Path | None = None, overrides: Iterable[str] = (),
                section: str | None = None) -> T:
    """Defaults, then the TOML file at ``path``, then ``KEY=VALUE`` overrides; validated."""
    changes: dict[str, Any] = {}
    if path:
        settings = read_config_file(path, section)
        types = _field_types(cls)
        # (TOML values are typed, unlike --set text: `h_min = "12"` is a string where a number
        # belongs, refused rather than read as one)
        for key, value in settings.items():
            if key in types:
                try:
                    _checked(key, types[key], value, _toml_text)
                except ConfigError as error:
                    raise ConfigError(f"{path}: {error}") from None
        changes.update(settings)
    changes.update(parse_overrides(overrides))
    return _apply(cls, {}, changes)


def replace_config(config: T, changes: dict[str, Any]) -> T:
    """A new validated config with ``changes`` applied; ``config`` itself is left unchanged."""
    return _apply(type(config), dataclasses.asdict(config), changes)


def config_to_dict(config: Any) -> dict[str, Any]:
    """The config's values as TOML, msgpack and JSON hold them (choices as plain strings)."""
    return {name: _plain(value) for name, value in dataclasses.asdict(config).items()}
