"""A TOML table read with checks: each value's type and range are checked as it is taken, and
any key left untaken is an error (:meth:`CheckedTable.finish`). Errors are
:class:`common.config.ConfigError` naming the file and the key's full path
(``balls[1].motion.speed``), so a user's typo is reported where it is."""

import math
from typing import Any

from balltrack.common.config import ConfigError


class CheckedTable:
    """A TOML table being read: hands out checked values and remembers which keys were used."""

    def __init__(self, data: Any, where: str, source: str):
        self.where = where
        self.source = source
        if not isinstance(data, dict):
            self.fail(where, f"expected a table, got {_kind(data)}")
        self.data = data
        self.used: set[str] = set()

    def fail(self, key: str, problem: str):
        raise ConfigError(f"{self.source}: {key}: {problem}")

    def path(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default: Any = None) -> Any:
        self.used.add(key)
        return self.data.get(key, default)

    def number(self, key: str, default: float | None = None, minimum: float | None = None,
               maximum: float | None = None, positive: bool = False) -> float:
        if key not in self.data:
            if default is None:
                self.fail(self.path(key), "missing (required)")
            return default
        value = self._number(self.path(key), self.raw(key))
        if positive and value <= 0:
            self.fail(self.path(key), f"must be > 0, got {value:g}")
        if minimum is not None and value < minimum:
            self.fail(self.path(key), f"must be >= {minimum:g}, got {value:g}")
        if maximum is not None and value > maximum:
            self.fail(self.path(key), f"must be <= {maximum:g}, got {value:g}")
        return value

    def _number(self, where: str, value: Any) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(where, f"expected a number, got {_kind(value)}")
        if not math.isfinite(value):
            self.fail(where, f"must be finite, got {value!r}")
        return float(value)

    def string(self, key: str, default: str | None = None,
               choices: tuple[str, ...] | None = None) -> str:
        if key not in self.data:
            if default is None:
                self.fail(self.path(key), "missing (required)")
            return default
        value = self.raw(key)
        if not isinstance(value, str):
            self.fail(self.path(key), f"expected a string, got {_kind(value)}")
        if choices is not None and value not in choices:
            self.fail(self.path(key), f"must be one of {', '.join(choices)}, got {value!r}")
        return value

    def vector(self, key: str, lengths: tuple[int, ...], default: tuple | None = None) -> tuple:
        if key not in self.data:
            if default is None:
                self.fail(self.path(key), "missing (required)")
            return default
        value = self.raw(key)
        where = self.path(key)
        if not isinstance(value, list):
            self.fail(where, f"expected a list of {_lengths(lengths)} numbers, got {_kind(value)}")
        if len(value) not in lengths:
            self.fail(where, f"expected {_lengths(lengths)} numbers, got {len(value)}")
        return tuple(self._number(f"{where}[{index}]", item) for index, item in enumerate(value))

    def colour(self, key: str, default: tuple[float, float, float] | None = None, grey_allowed: bool = False) -> tuple[float, float, float]:
        """An RGB colour in [0, 1]; with ``grey_allowed`` a single number means grey."""
        if grey_allowed and key in self.data and not isinstance(self.data[key], list):
            level = self.number(key)
            channels = (level, level, level)
        else:
            channels = self.vector(key, (3,), default)
        for channel in channels:
            if not 0.0 <= channel <= 1.0:
                self.fail(self.path(key),
                          f"colour values must be between 0 and 1, got {list(channels)}")
        return channels

    def table(self, key: str) -> "CheckedTable":
        return CheckedTable(self.raw(key, {}), self.path(key), self.source)

    def tables(self, key: str) -> list["CheckedTable"]:
        value = self.raw(key, [])
        if not isinstance(value, list):
            self.fail(self.path(key),
                      f"expected an array of tables ([[{key}]]), got {_kind(value)}")
        return [CheckedTable(item, f"{self.path(key)}[{index}]", self.source)
                for index, item in enumerate(value)]

    def finish(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            self.fail(self.path(unknown[0]), "unknown key")


def _kind(value: Any) -> str:
    if isinstance(value, bool):
        return f"a boolean ({value})"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, str):
        return f"a string ({value!r})"
    return f"{type(value).__name__} ({value!r})"


def _lengths(lengths: tuple[int, ...]) -> str:
    return " or ".join(str(length) for length in lengths)
