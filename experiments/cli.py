"""``balltrack experiment NAME [--quick] --out DIR [options]``: run experiments, write a report.

NAME is one of the experiments below or ``all``. Every run writes into DIR:

* ``results.json``: every figure under a stable name (``<experiment>/<condition>/<metric>``),
  the goals with PASS/MISS, merged with what DIR already holds (a rerun replaces its entry);
* ``report.md``: the tables (the paper's figures beside ours), the goals, how each experiment
  ran (in-process or over Zenoh) and the plots (PNG files, also in DIR).

Each experiment's entry also holds its date, this command and the machine's speed in the run
(``base.machine_speed``); ``python -m balltrack.experiments.results_doc DIR`` turns the file
into docs/results.md.

``--quick`` runs every experiment with small frame budgets (all of them in a few minutes);
``--frames N`` sets the budget per condition (frames, or runs for tracking) explicitly.

Examples::

    balltrack experiment all --quick --out runs/quick
    balltrack experiment illumination --frames 3 --out /tmp/illumination
    balltrack experiment real_photos --photos ../shared/data --out runs/photos
    balltrack experiment tracking --transport in-process --out runs/tracking
"""

import importlib
import shlex
import sys
import traceback
from pathlib import Path

from balltrack.common.arguments import ArgumentParser
from balltrack.common.terminal import exit_with
from balltrack.experiments.base import (PHOTOS_DEFAULT_TEXT, PHOTOS_VARIABLE, SHARED_PHOTOS, ExperimentResult,
                                        Options, Stopwatch, development_photos, machine_speed, write_outputs)
from balltrack.experiments.real_photos import photo_sets

EXPERIMENTS = ("illumination", "range", "accuracy", "tracking", "sizes", "multiball",
               "distractors", "real_photos", "detector_speed", "colour_setting", "latency", "live_view", "fuzz", "soak",
               "fleet")
TRANSPORTS = ("auto", "in-process", "zenoh")


def experiment_module(name: str):
    return importlib.import_module(f"balltrack.experiments.{name}")


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(prog="balltrack experiment", description=__doc__.split("\n\n")[0])
    parser.add_argument("name", metavar="NAME", help=f"one of {', '.join(EXPERIMENTS)}, or all")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    parser.add_argument("--quick", action="store_true", help="small frame budgets")
    parser.add_argument("--frames", type=int, default=None, metavar="N",
                        help="frames (tracking: runs) per condition, overriding the budget")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--photos", default=None, metavar="DIR",
                        help="labelled photos for real_photos: a set (images + labels.json) or a "
                             "folder of sets (every subfolder with labels.json); without it `all` "
                             f"(and detector_speed) use {PHOTOS_DEFAULT_TEXT}, when it holds sets")
    parser.add_argument("--transport", choices=TRANSPORTS, default="auto",
                        help="tracking: Zenoh services in lockstep (zenoh), the in-process loop, "
                             "or zenoh when the simulator service works (auto, default)")
    parser.add_argument("--detector", action="append", default=[], metavar="KEY=VALUE",
                        help="change a detector parameter for every experiment (repeatable)")
    parser.add_argument("--follower", action="append", default=[], metavar="KEY=VALUE",
                        help="change a follower parameter for the closed-loop experiments "
                             "(repeatable; overrides the experiment's own settings)")
    parser.add_argument("--view", action="append", default=[], metavar="KEY=VALUE",
                        help="live_view: change what `balltrack view` sends Rerun's page (repeatable)")
    parser.add_argument("--minutes", type=int, default=None, metavar="N",
                        help="soak: minutes to run (default 30, --quick 2)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    return parser


def parse(argv: list[str]) -> Options:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.name not in EXPERIMENTS and args.name != "all":
        parser.error(f"unknown experiment {args.name!r} (choose from {', '.join(EXPERIMENTS)}, all)")
    if args.minutes is not None and args.minutes < 1:
        parser.error(f"--minutes: must be >= 1, got {args.minutes}")
    if args.frames is not None and args.frames < 1:
        parser.error(f"--frames: must be >= 1, got {args.frames}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        parser.error(f"--out: {out} exists and is not a folder")
    photos = None
    if args.photos is not None:
        photos = Path(args.photos)
        if not photo_sets(photos):
            parser.error(f"--photos: {photos} has no labels.json, nor any subfolder with one")
    elif args.name == "real_photos":
        parser.error("real_photos needs --photos DIR (a labelled set, or a folder of them)")
    elif args.name == "all":
        photos = development_photos()
        if not photo_sets(photos):
            # The folder beside the repository may well be absent; one the variable names is a mistake.
            if photos != SHARED_PHOTOS:
                parser.error(f"${PHOTOS_VARIABLE}: {photos} has no labels.json, nor any subfolder with one")
            photos = None
    options = Options(out=out, quick=args.quick, frames=args.frames, seed=args.seed,
                      photos=photos, transport=args.transport, progress=not args.no_progress,
                      detector_overrides=args.detector, follower_overrides=args.follower,
                      view_overrides=args.view)
    try:
        options.detector_config()
        options.follower_config()
        options.view_config()
    except ValueError as error:  # ConfigError: unknown key or bad value
        parser.error(str(error))
    options.name = args.name  # type: ignore[attr-defined]
    options.minutes = args.minutes  # type: ignore[attr-defined]
    return options


def run_one(name: str, options: Options) -> tuple[ExperimentResult, bool]:
    """Run one experiment; a crash becomes an entry saying so (and a failed status)."""
    clock = Stopwatch()
    module = experiment_module(name)
    try:
        result = module.run(options)
        if options.detector_overrides:
            result.settings["detector changed from defaults"] = " ".join(options.detector_overrides)
        if options.follower_overrides:
            result.settings["follower changed (command line)"] = " ".join(options.follower_overrides)
        if options.view_overrides:
            result.settings["view changed (command line)"] = " ".join(options.view_overrides)
        return result, True
    except Exception as error:  # noqa: BLE001  (reported in results and on stderr)
        traceback.print_exc()
        result = ExperimentResult(name, getattr(module, "TITLE", name), mode="skipped",
                                  mode_note=f"crashed: {type(error).__name__}: {error}",
                                  quick=options.quick)
        result.figures[f"{name}/error"] = f"{type(error).__name__}: {error}"
        result.seconds = clock.seconds
        return result, False


def main(argv: list[str] | None = None) -> int:
    arguments = list(sys.argv[1:] if argv is None else argv)
    options = parse(arguments)
    names = list(EXPERIMENTS) if options.name == "all" else [options.name]
    options.out.mkdir(parents=True, exist_ok=True)
    clock = Stopwatch()
    ok = True
    speed: dict[str, float] = {}
    for name in names:
        print(f"[{name}] running{' (quick)' if options.quick else ''} ...", file=sys.stderr)
        result, succeeded = run_one(name, options)
        ok = ok and succeeded
        result.command = shlex.join(["balltrack", "experiment", *arguments])
        if not result.machine:  # (measured once per command, for the experiments that time nothing)
            speed = speed or machine_speed()
            result.machine = dict(speed)
        # Written after each experiment so that a long `all` leaves usable partial results.
        write_outputs(options.out, [result], list(EXPERIMENTS))
        missed = [goal.name for goal in result.goals if not goal.passed]
        print(f"[{name}] {result.mode}, {result.seconds:.0f} s, "
              f"{len(result.goals) - len(missed)}/{len(result.goals)} goals passed"
              + (f"; MISS: {', '.join(missed)}" if missed else ""), file=sys.stderr)
    print(f"wrote {options.out / 'results.json'} and {options.out / 'report.md'} "
          f"in {clock.seconds:.0f} s", file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    exit_with(main)
