"""The ``balltrack`` command's entry point (the console script and ``python -m balltrack``): light
on imports, so that a service's stop signals are caught before its heavy ones."""

import sys

from balltrack.common.shutdown import catch_early_stops


def main() -> int:
    # (services and the router: before their imports, so that a stop during them is not lost;
    # the other commands install their handlers, or none, as they go)
    if sys.argv[1:2] in (["run"], ["router"]):
        catch_early_stops()
    from balltrack.cli import entry_point

    return entry_point()
