"""The ``balltrack`` command, the top layer: it may import everything below it.

    balltrack run detector --set param2=18      # start one service (as `ros2 run`)
    balltrack router --listen tcp/0.0.0.0:7447  # a Zenoh router for one host
    balltrack deploy start --router             # router + services under the supervisor
    balltrack status                            # which services are alive, their stats
    balltrack echo detected_ball_3d --count 5
    balltrack hz camera/image_raw
    balltrack config detector v_min=30          # read or change parameters live
    balltrack config dump detector > d.yaml     # save them (config load detector d.yaml)
    balltrack topic list                        # live keys: type, publishers, subscribers, rate
    balltrack topic info detected_ball_3d
    balltrack pub cmd_vel '{linear: [0.1, 0, 0], angular: [0, 0, 0]}' [--rate 10]
    balltrack bw camera/image_raw               # bandwidth
    balltrack delay detected_ball_3d            # age of header stamps
    balltrack sim set_light diffuse=0.1         # drive the simulator
    balltrack detect photo1.jpg photo2.jpg      # the detector offline
    balltrack calibrate board*.jpg --board 9x6 --square 0.025 -o camera.yaml
    balltrack experiment range --quick --out runs/range
"""

import argparse
import sys

from balltrack.cli import (calibrate, config, introspect, network, offline, publish, recording, run,
                           topics)
from balltrack.cli import secure
from balltrack.cli import view
from balltrack.cli.session import check_keys
from balltrack.common.keys import Keys
from balltrack.common.session import client_config, secure_client_path, served_namespace
from balltrack.common.arguments import ArgumentParser
from balltrack.common.terminal import interruptible, silence_closed_stdout


def _experiment(arguments: list[str]) -> int:
    from balltrack.experiments.cli import main as experiment_main

    # (SIGTERM as Ctrl-C: the demos, routers and services an experiment started are stopped)
    return interruptible(lambda: experiment_main(arguments), "balltrack experiment")


def _deploy(arguments: list[str]) -> int:
    from balltrack.deploy.cli import main as deploy_main

    return deploy_main(arguments, prog="balltrack deploy")


def _train(arguments: list[str]) -> int:
    from balltrack.training.train import main as train_main

    return interruptible(lambda: train_main(arguments), "balltrack train")


# Commands with a parser of their own, handed every argument after their name (--help too).
DELEGATED = {"deploy": ("start or stop the system under the supervisor (deploy --help)", _deploy),
             "experiment": ("run an experiment (experiment --help)", _experiment),
             "train": ("train the learned detector's network on simulator renders (train --help)", _train)}


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(prog="balltrack", description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True, parser_class=ArgumentParser)
    run.register(commands)
    network.register(commands)
    config.register(commands)
    topics.register(commands)
    introspect.register(commands)
    publish.register(commands)
    offline.register(commands)
    calibrate.register(commands)
    recording.register(commands)
    secure.register(commands)
    view.register(commands)
    for name, (help_text, _) in DELEGATED.items():
        commands.add_parser(name, help=help_text, add_help=False)
    return parser


def entry_point() -> int:
    """The ``balltrack`` command (``python -m balltrack``): ``main``'s status, with SIGINT and
    SIGTERM ignored once it is known (see ``shutdown.ignore_stop_signals``)."""
    from balltrack.common.shutdown import ignore_stop_signals

    status = main()
    ignore_stop_signals()
    return status


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] in DELEGATED:
        return DELEGATED[argv[0]][1](argv[1:])
    args = build_parser().parse_args(argv)
    # (every networked command has a namespace; play's is None unless given: see recording.py)
    if hasattr(args, "namespace"):
        try:
            if args.namespace is not None:
                Keys(args.namespace)
            if args.command != "router":  # (the router builds a router's config, see network.py)
                # Zenoh refuses a bad --connect endpoint or --zenoh-config file when the
                # config is built: a bad argument, said before the command starts its work.
                client_config(getattr(args, "connect", None), getattr(args, "zenoh_config", None))
            if getattr(args, "secure", None) and hasattr(args, "role"):
                secure_client_path(args.secure, args.role, served_namespace(args))  # (the profile holds its role)
            # (the key a command watches or publishes, or the keys it records; play's keys are
            # the recording's, checked against it)
            if args.namespace is not None:
                check_keys([args.key] if getattr(args, "key", None) is not None else list(getattr(args, "keys", None) or []),
                           args.namespace)
        except ValueError as error:
            print(f"balltrack {args.command}: {error}", file=sys.stderr)
            return 2
    try:
        return args.handler(args)
    except BrokenPipeError:  # the reader of our output went away (`| head`): a normal end
        silence_closed_stdout()
        return 0

