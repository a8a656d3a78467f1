"""SimCommand requests checked before the simulation changes: a request from the network
(``sim/control``) is either wholly valid or refused with a one-line reason, never half applied,
and a reset names only a scenario file it may load (:func:`requested_scenario`). Pure
functions, no MuJoCo: :class:`sim.Simulation` applies what they return."""

import math
import os
import re
import stat
from pathlib import Path
from typing import Any

from balltrack.common.config import ConfigError
from balltrack.common.messages import shorten
from balltrack.services.simulator.scenario import SCENARIO_DIR, available_scenarios

# Each op and the arguments it takes (all optional in the request: an op says what it needs).
COMMAND_ARGUMENTS = {"reset": {"scenario"}, "set_light": {"diffuse", "ambient"},
                     "place_ball": {"id", "position"}, "place_robot": {"x", "y", "yaw"}}
COMMAND_OPS = tuple(COMMAND_ARGUMENTS)
# The height range (m) a placed ball's centre may be given.
MAX_BALL_HEIGHT = 10.0

# What a network request may name: a file stem, no path (see requested_scenario).
SCENARIO_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")


def finite_number(name: str, value: Any) -> float:
    """``value`` as a float; ValueError naming ``name`` for a non-number or a non-finite one."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name}: expected a number, got {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{name}: must be finite, got {value!r}")
    return number


def requested_light(diffuse: Any, ambient: Any) -> tuple[tuple[float, float, float] | None, ...]:
    """A set_light's ``(diffuse, ambient)``, each a checked level or None where not given;
    ValueError for neither given or a bad level."""
    if diffuse is None and ambient is None:
        raise ValueError("set_light: give diffuse and/or ambient")
    return tuple(None if value is None else light_level(name, value)
                 for name, value in (("diffuse", diffuse), ("ambient", ambient)))


def light_level(name: str, value: Any) -> tuple[float, float, float]:
    """A grey level or an [r, g, b] list, each in [0, 1]."""
    if isinstance(value, (list, tuple)):
        if len(value) != 3:
            raise ValueError(f"{name}: expected a number or [r, g, b], got {len(value)} values")
        channels = tuple(finite_number(f"{name}[{index}]", item)
                         for index, item in enumerate(value))
    else:
        level = finite_number(name, value)
        channels = (level, level, level)
    if any(not 0.0 <= channel <= 1.0 for channel in channels):
        # (as it was given: a grey level is not shown as the triple it stands for)
        raise ValueError(f"{name}: must be between 0 and 1, got {value!r}" if not isinstance(value, (list, tuple))
                         else f"{name}: values must be between 0 and 1, got {list(channels)}")
    return channels


def checked_request(request: Any) -> tuple[str, dict[str, Any]]:
    """The op of a SimCommand request and its arguments; ValueError for anything but a map
    with a known ``op`` and only that op's argument names (the values are checked by the op)."""
    if not isinstance(request, dict):
        raise ValueError(f"expected a map with an 'op', got {type(request).__name__}")
    op = request.get("op")
    if op not in COMMAND_OPS:
        raise ValueError(f"op: must be one of {', '.join(COMMAND_OPS)}, got {op!r}")
    arguments = {key: value for key, value in request.items() if key != "op"}
    allowed = COMMAND_ARGUMENTS[op]
    unknown = sorted(set(arguments) - allowed)
    if unknown:
        raise ValueError(f"{op}: unknown argument {unknown[0]!r} (allowed: {', '.join(sorted(allowed))})")
    return op, arguments


def checked_form(request: Any) -> tuple[str, dict[str, Any]]:
    """``checked_request``, and each argument's form as far as it does not depend on the world
    (types, light levels, the length of a position, required arguments): what a client can
    refuse before it sends the request. The simulator checks again, against its world."""
    op, arguments = checked_request(request)
    if op == "reset":
        scenario_name(arguments.get("scenario"))
    elif op == "set_light":
        requested_light(arguments.get("diffuse"), arguments.get("ambient"))
    elif op == "place_ball":
        if arguments.get("id") is None:
            raise ValueError("place_ball: missing 'id'")
        position_values(arguments.get("position"))
    else:
        robot_position(arguments.get("x"), arguments.get("y"), math.inf)
        if arguments.get("yaw") is not None:
            finite_number("yaw", arguments["yaw"])
    return op, arguments


def scenario_name(scenario: Any) -> str | None:
    """A reset's scenario name (None: the current scenario); ValueError for an empty or
    non-string one."""
    if scenario is not None and (not isinstance(scenario, str) or not scenario.strip()):
        raise ValueError(f"scenario: expected a scenario name, got {scenario!r}")
    return scenario


def ball_index(ball_id: Any, ids: list[str]) -> int:
    """Which of the scenario's balls ``ball_id`` names; ValueError listing them otherwise."""
    if ball_id is None:
        raise ValueError("place_ball: missing 'id'")
    if isinstance(ball_id, bool) or str(ball_id) not in ids:
        raise ValueError(f"id: no ball {ball_id!r} (balls: {', '.join(ids) or 'none'})")
    return ids.index(str(ball_id))


def ball_position(position: Any, radius: float, half_size: float) -> tuple[float, float, float]:
    """A ball's new centre from [x, y] (resting on the floor) or [x, y, z], inside the world."""
    values = position_values(position)
    limit = half_size - radius
    if abs(values[0]) > limit or abs(values[1]) > limit:
        raise ValueError(f"position: ({values[0]:g}, {values[1]:g}) is outside the world "
                         f"(|x|, |y| must be <= {limit:g})")
    if len(values) == 2:
        values.append(radius)
    if not 0.0 <= values[2] <= MAX_BALL_HEIGHT:
        raise ValueError(f"position: z must be between 0 and {MAX_BALL_HEIGHT:g} m, got {values[2]:g}")
    return values[0], values[1], values[2]


def position_values(position: Any) -> list[float]:
    """[x, y] or [x, y, z] as floats; ValueError for any other form."""
    if not isinstance(position, (list, tuple)) or len(position) not in (2, 3):
        raise ValueError(f"position: expected [x, y] or [x, y, z], got {position!r}")
    return [finite_number(f"position[{axis}]", value) for axis, value in enumerate(position)]


def robot_position(x: Any, y: Any, limit: float) -> tuple[float, float]:
    """The robot's new (x, y), both required, within ``limit`` of the world's centre."""
    if x is None or y is None:
        raise ValueError("place_robot: 'x' and 'y' are required")
    new_x, new_y = finite_number("x", x), finite_number("y", y)
    if abs(new_x) > limit or abs(new_y) > limit:
        raise ValueError(f"x, y: ({new_x:g}, {new_y:g}) is outside the world "
                         f"(|x|, |y| must be <= {limit:g})")
    return new_x, new_y


def requested_scenario(name: Any, folder: str | Path | None = None) -> Path:
    """The scenario file a network request (``sim/control`` reset) may load: a name, looked up
    among the shipped scenarios and then in ``folder`` (the folder of the scenario file the
    simulator was started with, if any), or the absolute path of a ``.toml`` file in ``folder``.
    A peer must not make the simulator read files of its choosing (``../../etc/hostname``,
    ``/dev/zero``): anything else, and anything that is not a regular file whose real location
    is one of those folders, is refused with ConfigError."""
    if not isinstance(name, str):
        raise ConfigError(f"scenario: expected a scenario name, got {type(name).__name__}")
    text = name.strip()
    folders = [SCENARIO_DIR.resolve()] + ([Path(folder).resolve()] if folder is not None else [])
    if "/" in text or "\\" in text:
        candidates = [Path(text)] if len(text) <= 4096 and Path(text).is_absolute() else []
        folders = folders[1:]  # a path names a file in the configured folder, never elsewhere
    else:
        candidates = [candidate_folder / (text if text.endswith(".toml") else f"{text}.toml")
                      for candidate_folder in folders]
    for candidate in candidates:
        if not (SCENARIO_NAME.fullmatch(candidate.stem) and candidate.suffix == ".toml"):
            break
        try:
            real = candidate.resolve(strict=True)
            if real.parent in folders and stat.S_ISREG(os.stat(real).st_mode):
                return real
        except (OSError, RuntimeError):  # missing, name too long, symlink loop
            continue
    known = ", ".join(available_scenarios())
    where = f"; or a .toml file in {folder}" if folder is not None else ""
    raise ConfigError(f"scenario: {shorten(repr(name), 80)} is not a scenario that may be loaded "
                      f"over the network (shipped: {known}{where})")
