"""Argparse types for the numbers commands take: a bad value is refused by argparse with one
line and status 2, before anything starts (``nan``, a negative count or a zero rate would
otherwise reach a division or a sleep).

Example::

    parser.add_argument("--seconds", type=number(above=0), default=20.0)
    parser.add_argument("--frames", type=integer(minimum=1), default=150)
"""

import argparse
import math
from typing import Callable


def number(minimum: float | None = None, above: float | None = None) -> Callable[[str], float]:
    """A finite float, at least ``minimum`` or greater than ``above`` (when given)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be a finite number, got {text}")
        if minimum is not None and value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum:g}, got {text}")
        if above is not None and value <= above:
            raise argparse.ArgumentTypeError(f"must be greater than {above:g}, got {text}")
        return value
    return parse


def integer(minimum: int | None = None) -> Callable[[str], int]:
    """A whole number, at least ``minimum`` (when given)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if minimum is not None and value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {text}")
        return value
    return parse
