"""common.arguments: the commands' parser and the argparse types that refuse bad numbers before a
command starts."""

import argparse

import pytest

from balltrack.common.arguments import ArgumentParser, integer, number, unwritable_reason


@pytest.mark.parametrize("text, reason", [("nan", "finite"), ("inf", "finite"), ("-1", "at least 0"),
                                          ("x", "expected a number")])
def test_number_refuses(text, reason):
    with pytest.raises(argparse.ArgumentTypeError, match=reason):
        number(minimum=0)(text)


def test_number_above_excludes_the_bound_and_minimum_includes_it():
    with pytest.raises(argparse.ArgumentTypeError, match="greater than 0"):
        number(above=0)("0")
    assert number(above=0)("0.5") == 0.5
    assert number(minimum=0)("0") == 0.0


@pytest.mark.parametrize("text, reason", [("0", "at least 1"), ("1.5", "whole number"), ("nan", "whole number")])
def test_integer_refuses(text, reason):
    with pytest.raises(argparse.ArgumentTypeError, match=reason):
        integer(minimum=1)(text)


def test_a_parser_gives_one_line_and_status_2(capsys):
    parser = ArgumentParser(prog="tool")
    parser.add_argument("--frames", type=integer(minimum=1))
    assert parser.parse_args(["--frames", "3"]).frames == 3
    with pytest.raises(SystemExit) as exit_info:
        parser.parse_args(["--frames", "0"])
    assert exit_info.value.code == 2
    # the reason alone, no usage block
    assert capsys.readouterr().err.strip().splitlines() == ["tool: argument --frames: must be at least 1, got 0"]


def test_an_unwritable_output_is_named_before_anything_is_made(tmp_path):
    assert unwritable_reason(tmp_path / "run.mcap") is None
    assert unwritable_reason(tmp_path) == "Is a directory"
    assert unwritable_reason(tmp_path / "missing" / "run.mcap") == f"{tmp_path / 'missing'} is no folder"
    (tmp_path / "file").write_text("")
    assert unwritable_reason(tmp_path / "file" / "run.mcap") == f"{tmp_path / 'file'} is no folder"
    assert list(tmp_path.iterdir()) == [tmp_path / "file"]  # (nothing made)


@pytest.mark.parametrize("argv, named", [(["info", "x", "--bogus"], "tool info"),
                                         (["topic", "info", "k", "--bogus"], "tool topic info"),
                                         (["--bogus", "info", "x"], "tool info")])
def test_an_unknown_option_is_named_by_the_innermost_subcommand(capsys, argv, named):
    parser = ArgumentParser(prog="tool")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=ArgumentParser)
    commands.add_parser("info").add_argument("file")
    topic = commands.add_parser("topic").add_subparsers(dest="action", required=True, parser_class=ArgumentParser)
    topic.add_parser("info").add_argument("key")
    with pytest.raises(SystemExit) as exit_info:
        parser.parse_args(argv)
    assert exit_info.value.code == 2
    assert capsys.readouterr().err.strip().splitlines() == [f"{named}: unrecognized arguments: --bogus"]
    assert parser.parse_args(["info", "x"]).file == "x"


@pytest.mark.parametrize("argv, rest", [
    (["config", "locator", "--connect", "tcp/h:1", "a=1", "b=2"], ["a=1", "b=2"]),
    (["config", "locator", "a=1", "--connect", "tcp/h:1", "b=2"], ["a=1", "b=2"]),
    (["config", "locator", "a=1", "b=2", "--connect", "tcp/h:1"], ["a=1", "b=2"]),
    (["config", "--connect", "tcp/h:1", "locator", "a=1"], ["a=1"])])
def test_values_of_a_last_positional_may_follow_options(argv, rest):
    parser = ArgumentParser(prog="tool")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=ArgumentParser)
    config = commands.add_parser("config")
    config.add_argument("target")
    config.add_argument("rest", nargs="*")
    config.add_argument("--connect")
    parsed = parser.parse_args(argv)
    assert (parsed.target, parsed.rest, parsed.connect) == ("locator", rest, "tcp/h:1")


def test_an_unknown_option_among_trailing_values_is_still_refused(capsys):
    parser = ArgumentParser(prog="tool")
    parser.add_argument("target")
    parser.add_argument("rest", nargs="*")
    parser.add_argument("--connect")
    with pytest.raises(SystemExit):
        parser.parse_args(["locator", "--connect", "x", "a=1", "--bogus", "b=2"])
    assert capsys.readouterr().err.strip() == "tool: unrecognized arguments: --bogus"


@pytest.mark.parametrize("argv, required", [(["sim"], "op"), (["config"], "SERVICE|dump|load")])
def test_only_what_is_required_is_named_as_required(capsys, argv, required):
    # (KEY=VALUE may be left out: `balltrack sim reset`, `balltrack config locator`)
    from balltrack.cli import build_parser
    with pytest.raises(SystemExit) as exit_info:
        build_parser().parse_args(argv)
    assert exit_info.value.code == 2
    assert capsys.readouterr().err.strip() == (f"balltrack {argv[0]}: the following arguments are "
                                               f"required: {required}")
