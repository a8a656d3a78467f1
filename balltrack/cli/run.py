"""``balltrack run SERVICE [options]``: start one service in this process, as ``ros2 run`` does.

The same as ``python -m balltrack.services.SERVICE [options]``; the options are the service's
own (``balltrack run detector --help``).
"""

import argparse
import importlib
import sys

from balltrack.common.keys import PROCESS_JOIN, SERVICES, process_services

# `balltrack run A+B --help`'s description.
JOINED_HELP = """``balltrack run detector+locator [options]`` runs several services in one process on one
Zenoh session, as a ROS 2 component container does: a message from one to the other is a
call, not a hop between processes. Settings and files then name their service: ``--set
locator.mode=exact``, ``--config detector=detector.toml``. Not with ``--secure``, where each
service has a certificate (a role) of its own. With ``--namespaces robot1,robot2`` (or ``auto``)
the process serves several robots, each service built once per robot under its namespace.
"""


def command_run(args) -> int:
    names = process_services(args.service)
    unknown = [name for name in names if name not in SERVICES]
    if unknown or len(set(names)) != len(names):
        print(f"balltrack run: {args.service}: expected SERVICE or SERVICE{PROCESS_JOIN}SERVICE..., "
              f"each once, of {', '.join(SERVICES)}", file=sys.stderr)
        return 2
    # Imported by name: the CLI sits above every service, and a service's heavy imports
    # (MuJoCo, OpenCV) are paid only by the one that runs.
    modules = [importlib.import_module(f"balltrack.services.{name}.service") for name in names]
    if len(modules) == 1:
        return modules[0].main(args.arguments)
    # (a service that cannot run on this machine says why, as its own main does)
    for name, module in zip(names, modules):
        reason = module.unavailable() if hasattr(module, "unavailable") else None
        if reason:
            print(f"balltrack run: {name}: {reason}", file=sys.stderr)
            return 2
    from balltrack.common.runner import run_services

    return run_services([(name, module.CONFIG, module.build) for name, module in zip(names, modules)],
                        args.arguments, JOINED_HELP)


def register(commands) -> None:
    run = commands.add_parser("run", help="start one service (options: balltrack run SERVICE --help)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    run.add_argument("service", metavar="SERVICE",
                     help=f"one of {', '.join(SERVICES)}, or several joined by {PROCESS_JOIN} (one process)")
    run.add_argument("arguments", nargs=argparse.REMAINDER, metavar="...",
                     help="the service's options")
    run.set_defaults(handler=command_run)
