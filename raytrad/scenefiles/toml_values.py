"""Checked values of a TOML scene file, each error naming the file and the dotted key.

:class:`Key` is a position in the file (``mesh[0].materials.white.reflectance``); the
functions here return a value of the wanted type and range or raise the
:class:`~raytrad.errors.SceneError` that names it.
"""

from __future__ import annotations

import difflib
import json
import math
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.errors import SceneError

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


@dataclass(frozen=True)
class Key:
    """A dotted key inside one TOML file, for error messages."""

    file: Path
    dotted: str = ""

    def __truediv__(self, name: str) -> Key:
        part = name if _BARE_KEY.match(name) else json.dumps(name)
        return Key(self.file, f"{self.dotted}.{part}" if self.dotted else part)

    def index(self, i: int) -> Key:
        return Key(self.file, f"{self.dotted}[{i}]")

    def error(self, problem: str) -> SceneError:
        return SceneError(self.file, f"{self.dotted}: {problem}")


def show(value: Any) -> str:
    """A TOML value as a short string for messages."""
    text = json.dumps(value) if isinstance(value, str | list | bool) else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def table(key: Key, value: Any, allowed: Iterable[str]) -> dict[str, Any]:
    """``value`` as a table whose keys are all in ``allowed``."""
    if not isinstance(value, dict):
        raise key.error(f"expected a table, got {show(value)}")
    allowed = tuple(allowed)
    for name in value:
        if name not in allowed:
            close = difflib.get_close_matches(name, allowed, n=1)
            hint = f"did you mean {close[0]!r}?" if close else f"allowed: {', '.join(allowed)}"
            raise SceneError(key.file, f"unknown key '{(key / name).dotted}' ({hint})")
    return value


def required(key: Key, table: dict[str, Any], name: str) -> Any:
    if name not in table:
        raise SceneError(key.file, f"missing key '{(key / name).dotted}'")
    return table[name]


def one_of(key: Key, table: dict[str, Any], names: Iterable[str]) -> str | None:
    """The one key of ``names`` the table gives, None if none; an error if several."""
    given = [n for n in names if n in table]
    if len(given) > 1:
        raise (key / given[1]).error(f"cannot be combined with '{(key / given[0]).dotted}'")
    return given[0] if given else None


def is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def number(
    key: Key,
    value: Any,
    low: float = -math.inf,
    high: float = math.inf,
    low_open: bool = False,
) -> float:
    """A finite number in [low, high] (or (low, high] with ``low_open``)."""
    if not is_number(value):
        raise key.error(f"expected a number, got {show(value)}")
    number = float(value)
    below = number <= low if low_open else number < low
    if not math.isfinite(number) or below or number > high:
        opening = "(" if low_open else "["
        raise key.error(f"{number:g} is outside {opening}{low:g}, {high:g}]")
    return number


def numbers(
    key: Key, value: Any, count: int | None, low: float = -math.inf, high: float = math.inf
) -> np.ndarray:
    """(count,) float64 from a list of finite numbers in [low, high]; any length >= 2 if None."""
    wanted = f"a list of {count} numbers" if count else "a list of numbers"
    if not isinstance(value, list) or not all(is_number(v) for v in value):
        raise key.error(f"expected {wanted}, got {show(value)}")
    if (count is not None and len(value) != count) or (count is None and len(value) < 2):
        raise key.error(f"expected {wanted if count else 'at least 2 numbers'}, got {len(value)}")
    array = np.array(value, dtype=np.float64)
    bad = ~np.isfinite(array) | (array < low) | (array > high)
    if bad.any():
        raise key.error(f"{array[bad][0]:g} is outside [{low:g}, {high:g}]")
    return array


def rgb(key: Key, value: Any, low: float = 0.0, high: float = math.inf) -> np.ndarray:
    """(3,) float64 from one number (grey) or three, each in [low, high]."""
    if is_number(value):
        return np.full(3, number(key, value, low, high))
    if isinstance(value, list):
        return numbers(key, value, 3, low, high)
    raise key.error(f"expected a number or a list of 3 numbers, got {show(value)}")


def string(key: Key, value: Any) -> str:
    if not isinstance(value, str):
        raise key.error(f"expected a string, got {show(value)}")
    return value


def boolean(key: Key, value: Any) -> bool:
    if not isinstance(value, bool):
        raise key.error(f"expected true or false, got {show(value)}")
    return value


def colorimetry(key: Key, function: Callable[..., np.ndarray], *args: Any) -> np.ndarray:
    """Call a :mod:`raytrad.scene.colorimetry` function, its ValueError naming the key."""
    try:
        return np.asarray(function(*args), dtype=np.float64)
    except ValueError as exc:
        raise key.error(str(exc)) from None


def triple(values: np.ndarray) -> tuple[float, float, float]:
    return (float(values[0]), float(values[1]), float(values[2]))
