"""``balltrack`` (the console script) and ``python -m balltrack``."""

import sys

from balltrack.common.shutdown import catch_early_stops


def main() -> int:
    # (services and the router: before their imports, so that a stop during them is not lost;
    # the other commands install their handlers, or none, as they go)
    if sys.argv[1:2] in (["run"], ["router"]):
        catch_early_stops()
    from balltrack.cli import entry_point

    return entry_point()


if __name__ == "__main__":
    sys.exit(main())
