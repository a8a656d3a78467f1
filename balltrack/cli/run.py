"""``balltrack run SERVICE [options]``: start one service in this process, as ``ros2 run`` does.

The same as ``python -m balltrack.services.SERVICE [options]``; the options are the service's
own (``balltrack run detector --help``).
"""

import argparse
import importlib

from balltrack.common.keys import SERVICES


def command_run(args) -> int:
    # Imported by name: the CLI sits above every service, and a service's heavy imports
    # (MuJoCo, OpenCV) are paid only by the one that runs.
    service = importlib.import_module(f"balltrack.services.{args.service}.service")
    return service.main(args.arguments)


def register(commands) -> None:
    run = commands.add_parser("run", help="start one service (options: balltrack run SERVICE --help)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    run.add_argument("service", choices=SERVICES, metavar="SERVICE",
                     help=f"one of {', '.join(SERVICES)}")
    run.add_argument("arguments", nargs=argparse.REMAINDER, metavar="...",
                     help="the service's options")
    run.set_defaults(handler=command_run)
