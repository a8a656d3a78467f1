"""Each parameter declared once (common.config.param): validation, choices, describe and --help
all read the same declaration, for every service's config."""

import dataclasses
import enum
import importlib
import math
import re
import subprocess
import sys
import typing

import msgpack
import pytest

from balltrack.common.config import (ConfigError, check_fields, config_to_dict, declaration,
                                     describe_config, format_value, help_text, load_config, param,
                                     replace_config)
from balltrack.common.messages import decode, encode
from balltrack.common.runner import build_parser
from balltrack.services.detector.config import DetectorConfig
from balltrack.deploy import params
from tests.harness import REPO, process_environment

CONFIGS = {service: params.config_class(module_name, class_name)
           for service, module_name, class_name in params.CONFIGS}


def fields_of(cls):
    hints = typing.get_type_hints(cls)
    return [(field, hints[field.name]) for field in dataclasses.fields(cls)]


def every_field(predicate=lambda field, annotation: True):
    return [pytest.param(cls, field, annotation, id=f"{service}.{field.name}")
            for service, cls in CONFIGS.items() for field, annotation in fields_of(cls)
            if predicate(field, annotation)]


def is_choice(annotation):
    return isinstance(annotation, type) and issubclass(annotation, enum.Enum)


def outside_values(field, annotation):
    """Values just past each declared bound (and not the field's ``off`` value)."""
    declared = declaration(field)
    values = []
    if declared.low is not None:
        values.append(declared.low if declared.low_open else
                      declared.low - (1 if annotation is int else 0.5))
    if declared.high is not None:
        values.append(declared.high if declared.high_open else
                      declared.high + (1 if annotation is int else 0.5))
    return [annotation(value) for value in values if value != declared.off]


@pytest.mark.parametrize("service, cls", CONFIGS.items())
def test_every_field_is_declared_with_a_distinct_one_line_meaning(service, cls):
    meanings = {}
    for field, _ in fields_of(cls):
        declared = declaration(field)
        assert declared is not None, f"{service}.{field.name} is not declared with param()"
        assert declared.meaning.strip() and "\n" not in declared.meaning, f"{service}.{field.name}"
        meanings.setdefault(declared.meaning, []).append(field.name)
    shared = {meaning: names for meaning, names in meanings.items() if len(names) > 1}
    assert not shared, f"{service}: parameters share a meaning: {shared}"


@pytest.mark.parametrize("cls, field, annotation", every_field(
    lambda field, annotation: annotation in (int, float) and outside_values(field, annotation)))
def test_stated_bounds_are_the_enforced_ones(cls, field, annotation):
    # A bound printed rounded (pi as 3.14159) tells the user a value is refused that is not.
    declared = declaration(field)
    stated = describe_config(cls)[field.name]["bounds"]
    numbers = [float(text) for text in re.findall(r"-?\d+(?:\.\d+)?(?:e[-+]?\d+)?", stated)]
    enforced = [bound for bound in (declared.off, declared.low, declared.high) if bound is not None]
    assert numbers == [float(bound) for bound in enforced], (stated, enforced)


@pytest.mark.parametrize("cls, field, annotation", every_field(
    lambda field, annotation: annotation in (int, float) and outside_values(field, annotation)))
def test_values_past_a_bound_are_refused_in_one_line_naming_the_field(cls, field, annotation):
    for value in outside_values(field, annotation):
        with pytest.raises(ConfigError) as caught:
            cls(**{field.name: value})
        message = str(caught.value)
        assert message.startswith(f"{field.name}: must be "), message
        assert "\n" not in message and repr(value) in message
        # The same refusal through --set and the live path (replace_config).
        with pytest.raises(ConfigError, match=f"^{field.name}: must be "):
            load_config(cls, overrides=[f"{field.name}={value}"])
        with pytest.raises(ConfigError, match=f"^{field.name}: must be "):
            replace_config(cls(), {field.name: value})


@pytest.mark.parametrize("cls, field, annotation", every_field(
    lambda field, annotation: annotation in (int, float, bool, str) or is_choice(annotation)))
def test_wrong_types_are_refused_in_one_line_naming_the_field(cls, field, annotation):
    wrong = {int: [1.5, True, "3"], float: [True, "1.0", math.nan, math.inf], bool: [1, "yes", None],
             str: [3, None]}.get(annotation, [3, None, True])
    for value in wrong:
        with pytest.raises(ConfigError) as caught:
            cls(**{field.name: value})
        assert str(caught.value).startswith(f"{field.name}: ") and "\n" not in str(caught.value)


@pytest.mark.parametrize("cls, field, annotation", every_field(
    lambda field, annotation: annotation in (int, float)))
def test_text_that_is_no_number_is_refused_as_what_was_expected(cls, field, annotation):
    # (not Python's "invalid literal for int() with base 10")
    expected = "an integer" if annotation is int else "a number"
    for text in (["1.5", "abc", "", "[1]"] if annotation is int else ["abc", "", "1,5"]):
        with pytest.raises(ConfigError) as caught:
            load_config(cls, overrides=[f"{field.name}={text}"])
        assert str(caught.value) == f"{field.name}: expected {expected}, got {text!r}"


@pytest.mark.parametrize("cls, field, annotation", every_field(lambda field, annotation: is_choice(annotation)))
def test_choices_round_trip_as_plain_strings(cls, field, annotation, tmp_path):
    choices = [member.value for member in annotation]
    assert describe_config(cls)[field.name]["choices"] == choices
    with pytest.raises(ConfigError, match=rf"^{field.name}: must be one of {', '.join(choices)}, got 'warp'$"):
        load_config(cls, overrides=[f"{field.name}=warp"])
    for choice in choices:
        from_set = load_config(cls, overrides=[f"{field.name}={choice}"])
        path = tmp_path / f"{choice}.toml"
        path.write_text(f'{field.name} = "{choice}"\n')
        from_file = load_config(cls, path)
        replaced = replace_config(cls(), {field.name: choice})
        constructed = cls(**{field.name: choice})
        for config in (from_set, from_file, replaced, constructed):
            value = getattr(config, field.name)
            assert value == choice and isinstance(value, annotation) and f"{value}" == choice
            plain = config_to_dict(config)[field.name]
            assert type(plain) is str and plain == choice
        # Out through msgpack (the live ConfigReply) and back in through --set and a TOML file.
        reply = decode("ConfigReply", encode("ConfigReply", {"ok": True, "config": config_to_dict(from_set)}))
        assert reply["config"] == config_to_dict(from_set)
        assert msgpack.unpackb(msgpack.packb(getattr(from_set, field.name))) == choice
        toml = tmp_path / "dumped.toml"
        toml.write_text("".join(f"{name} = {format_value(value)}\n"
                                for name, value in reply["config"].items()))
        assert load_config(cls, toml) == from_set


@pytest.mark.parametrize("service, cls", CONFIGS.items())
def test_describe_matches_the_declarations_and_travels_in_a_config_reply(service, cls):
    described = describe_config(cls)
    defaults = config_to_dict(cls())
    assert list(described) == list(defaults)
    for field, annotation in fields_of(cls):
        entry, declared = described[field.name], declaration(field)
        assert entry["default"] == defaults[field.name] and type(entry["default"]) is type(defaults[field.name])
        assert (entry["meaning"], entry["low"], entry["high"]) == (declared.meaning, declared.low, declared.high)
        assert entry["type"] == ("str" if is_choice(annotation) else annotation.__name__)
        # A default always lies within its own bounds.
        if entry["low"] is not None and entry["default"] != entry["off"]:
            assert entry["default"] > entry["low"] if entry["low_open"] else entry["default"] >= entry["low"]
    reply = decode("ConfigReply", encode("ConfigReply", {"ok": True, "config": defaults,
                                                         "parameters": described}))
    assert reply["parameters"] == described


def test_describe_reply_is_validated():
    with pytest.raises(Exception, match="parameters.gain.meaning"):
        encode("ConfigReply", {"ok": True, "parameters": {"gain": {"type": "float", "meaning": 3}}})
    with pytest.raises(Exception, match="describe"):
        encode("ConfigRequest", {"describe": "yes"})


@pytest.mark.parametrize("service, cls", CONFIGS.items())
def test_help_lists_every_parameter_with_type_default_bounds_and_meaning(service, cls):
    text = build_parser(service, "", cls).format_help()
    assert "parameters (--set NAME=VALUE" in text
    for name, entry in describe_config(cls).items():
        line = next((line for line in text.splitlines() if line.startswith(f"  {name} = ")), None)
        assert line is not None, f"--help of {service} lacks {name}"
        assert format_value(entry["default"]) in line and entry["type"] in line and entry["bounds"] in line
        for choice in entry["choices"] or ():
            assert choice in line
        first_words = " ".join(entry["meaning"].replace("`", "").split()[:4])
        assert first_words in " ".join(text.split()), f"{service}.{name}: meaning missing"


def test_balltrack_run_help_shows_the_parameters():
    # The real command, as a person types it; the follower is the lightest service to import.
    result = subprocess.run([sys.executable, "-m", "balltrack", "run", "follower", "--help"],
                            capture_output=True, text=True, timeout=60, cwd=REPO, env=process_environment())
    assert result.returncode == 0, result.stderr
    assert result.stdout.endswith(help_text(CONFIGS["follower"]) + "\n")


def test_generic_rules_of_param():
    class Speed(enum.StrEnum):
        slow = "slow"
        fast = "fast"

    @dataclasses.dataclass
    class Example:
        gain: float = param(0.5, "loop gain", low=0, below=1)
        limit: int = param(0, "largest count; 0 = none", low=8, off=0)
        speed: Speed = param(Speed.slow, "how fast")
        levels: list[float] = param([0.1, 0.2], "levels")

        def __post_init__(self):
            check_fields(self)

    assert Example(gain=0).gain == 0.0 and isinstance(Example(gain=0).gain, float)
    assert Example(limit=0).limit == 0 and Example(limit=8).limit == 8
    assert Example().levels is not Example().levels  # a list default is not shared
    with pytest.raises(ConfigError, match=r"^gain: must be in \[0, 1\), got 1.0$"):
        Example(gain=1)
    with pytest.raises(ConfigError, match=r"^limit: must be 0 or >= 8, got 3$"):
        Example(limit=3)
    assert Example(speed="fast").speed is Speed.fast
    assert describe_config(Example)["speed"]["choices"] == ["slow", "fast"]
    assert describe_config(Example)["levels"]["default"] == [0.1, 0.2]
    with pytest.raises(TypeError):
        param(1.0, "both bounds on one side", low=0, above=0)


@pytest.mark.parametrize("line, reason", [
    ('h_min = "12"', 'h_min: expected an integer, got "12"'),
    ("h_min = true", "h_min: expected an integer, got true"),
    ("h_min = 12.5", "h_min: expected an integer, got 12.5"),
    ('min_score = "0.5"', 'min_score: expected a number, got "0.5"'),
    ("min_score = false", "min_score: expected a number, got false"),
])
def test_a_toml_value_of_the_wrong_type_is_refused_as_toml_spells_it(tmp_path, line, reason):
    # (TOML values are typed: a quoted number is a string, not read as the number it spells)
    path = tmp_path / "detector.toml"
    path.write_text(line + "\n")
    with pytest.raises(ConfigError) as raised:
        load_config(DetectorConfig, path, section="detector")
    assert str(raised.value) == f"{path}: {reason}"


def test_toml_values_of_their_fields_types_load_and_text_overrides_still_coerce(tmp_path):
    path = tmp_path / "detector.toml"
    path.write_text("h_min = 12\nmin_score = 1\n[detector]\nwork_width = 320\n")
    config = load_config(DetectorConfig, path, ["h_max=40", "min_colourfulness=0.3"], section="detector")
    assert (config.h_min, config.min_score, config.work_width, config.h_max, config.min_colourfulness) == \
        (12, 1.0, 320, 40, 0.3)


@pytest.mark.parametrize("service, setting", [
    # (each was taken: 1e6 threads exhausted the host's processes; the others made a wait of
    # 1e300 s, an OverflowError that killed the follower's timer, the camera or the simulator)
    ("detector", "threads=1000000"),
    ("follower", "rate_hz=1e-300"),
    ("camera", "rate_hz=1e-300"),
    ("simulator", "real_time_factor=1e-300"),
    ("simulator", "lockstep_timeout=1e300"),
    ("simulator", "lockstep_command_rate_hz=1e-300"),
])
def test_a_setting_that_would_stall_or_exhaust_a_service_is_refused(service, setting):
    name = setting.partition("=")[0]
    with pytest.raises(ConfigError, match=f"^{name}: must be"):
        load_config(CONFIGS[service], overrides=[setting])


@pytest.mark.parametrize("service", ["camera", "simulator"])
def test_the_settings_marked_live_are_those_a_running_service_changes(service):
    # (the tables marked 2 of the simulator's 7 and 3 of the camera's 4)
    live = importlib.import_module(f"balltrack.services.{service}.config").LIVE_SETTINGS
    marked = {name for name, described in describe_config(CONFIGS[service]).items()
              if described["meaning"].endswith("can be changed live")}
    assert marked == live
