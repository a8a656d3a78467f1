"""The argument parser of every command, and argparse types for the numbers commands take: a
bad argument is refused with one line and status 2, before anything starts (``nan``, a
negative count or a zero rate would otherwise reach a division or a sleep).

Example::

    parser = ArgumentParser(prog="python -m balltrack.experiments.locator_table")
    parser.add_argument("--seconds", type=number(above=0), default=20.0)
    parser.add_argument("--frames", type=integer(minimum=1), default=150)
"""

import argparse
import math
import os
from typing import Callable


class ArgumentParser(argparse.ArgumentParser):
    """argparse with a one-line error (the reason, not the usage block) and exit status 2; an
    option no (sub)command knows is reported by the subcommand given (``balltrack info:
    unrecognized arguments: --bogus``), not by the top-level command."""

    def __init__(self, *arguments, **options):
        super().__init__(*arguments, **options)
        # (a subcommand's defaults overwrite its parent's: the innermost one given is named)
        self.set_defaults(parser_of_command=self)

    def error(self, message: str):
        self.exit(2, f"{self.prog}: {message}\n")

    def parse_args(self, args=None, namespace=None):
        parsed, extras = self.parse_known_args(args, namespace)
        command = getattr(parsed, "parser_of_command", self)
        extras = command._take_trailing_values(parsed, extras)
        if extras:
            command.error(f"unrecognized arguments: {' '.join(extras)}")
        return parsed

    def _take_trailing_values(self, parsed, extras: list[str]) -> list[str]:
        """Values of a last any-number positional given after an option (``config locator
        --connect X a=1 b=2``), which argparse leaves over once the positionals before the
        option were taken; the extras left."""
        positionals = [action for action in self._actions if not action.option_strings]
        if not extras or not positionals or positionals[-1].nargs not in ("*", "+"):
            return extras
        last = positionals[-1]
        values = [extra for extra in extras if not extra.startswith("-")]
        if values and last.type is None and last.choices is None:
            setattr(parsed, last.dest, list(getattr(parsed, last.dest) or []) + values)
            return [extra for extra in extras if extra.startswith("-")]
        return extras


def number(minimum: float | None = None, above: float | None = None,
           maximum: float | None = None) -> Callable[[str], float]:
    """A finite float, at least ``minimum`` or greater than ``above``, and at most ``maximum``
    (when given)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be a finite number, got {text}")
        if minimum is not None and value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {_shown(minimum)}, got {text}")
        if above is not None and value <= above:
            raise argparse.ArgumentTypeError(f"must be greater than {_shown(above)}, got {text}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"must be at most {_shown(maximum)}, got {text}")
        return value
    return parse


def _shown(bound: float) -> str:
    """A bound as a person writes it: 10000000, 0.01."""
    return str(int(bound)) if float(bound).is_integer() and abs(bound) < 1e15 else f"{bound:g}"


# The longest time (s) a command's option may ask it to wait or run: 116 days. Python's waits
# refuse more than ~9.2e9 s (OverflowError), Zenoh's timeouts are in ms.
LONGEST_SECONDS = 1e7


def zero_or(minimum: float, maximum: float, zero: str) -> Callable[[str], float]:
    """0 (meaning ``zero``: "once", "as fast as possible") or a number from ``minimum`` to
    ``maximum``: a rate, whose period must stay a time a command can wait."""
    within = number(minimum=0, maximum=maximum)

    def parse(text: str) -> float:
        value = within(text)
        if 0 < value < minimum:
            raise argparse.ArgumentTypeError(f"must be 0 ({zero}) or at least {_shown(minimum)}, got {text}")
        return value
    return parse


def seconds(minimum: float | None = None, above: float | None = None) -> Callable[[str], float]:
    """``number`` for a time in seconds: at most LONGEST_SECONDS."""
    return number(minimum, above, LONGEST_SECONDS)


def integer(minimum: int | None = None, maximum: int | None = None) -> Callable[[str], int]:
    """A whole number, at least ``minimum`` and at most ``maximum`` (when given)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if minimum is not None and value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {text}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"must be at most {maximum}, got {text}")
        return value
    return parse


def unwritable_reason(path: str | os.PathLike) -> str | None:
    """Why a file cannot be written at ``path`` (it is a folder, its folder does not exist or
    may not be written in), found without creating anything; None when it looks writable.
    For a command to refuse its output option before it does any work or waits for a router;
    opening the file may still fail (a full disk), and the command says so then."""
    path = os.fspath(path)
    if os.path.isdir(path):
        return "Is a directory"
    folder = os.path.dirname(path) or "."
    if not os.path.isdir(folder):
        return f"{folder} is no folder"
    if not os.access(folder, os.W_OK | os.X_OK):
        return "Permission denied"
    return None
