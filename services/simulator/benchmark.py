"""The simulator core's speed, without pacing or Zenoh: render-only and step-only ms per frame,
and frames per second of the fast mode (step, render and ground truth back to back), with the
CPU time a fast-mode frame takes in all of the process's threads (the rasteriser's included),
which another load on the machine changes less than the wall times. Every
robot's camera is rendered each frame, so with ``robots`` > 1 render_ms is a frame's renders
of all of them.

Example::

    python -m balltrack.services.simulator.benchmark --frames 150 --set shadows=true
    python -m balltrack.services.simulator.benchmark --set scenario=fleet --set width=320 \\
        --set height=240 --set rate_hz=15 --robots 1 2 4 8 16
"""

import math
import time

from balltrack.common.arguments import ArgumentParser, integer
from balltrack.common.config import ConfigError, load_config, replace_config
from balltrack.common.terminal import exit_with
from balltrack.services.simulator.config import SimulatorConfig
from balltrack.services.simulator.sim import Simulation


def benchmark(config: SimulatorConfig, frames: int = 150) -> dict[str, float]:
    """Time the frame loop without pacing: render-only ms/frame, step-only ms, fast-mode fps
    and fast-mode CPU ms/frame."""
    simulation = Simulation(config)
    robots = range(simulation.robot_count)

    def command(frame: int) -> None:
        for robot in robots:
            simulation.set_command(0.3, 0.5 * math.sin(frame / 10 + robot), simulation.time, robot)

    try:
        for robot in robots:  # warm-up: first render compiles shaders / uploads textures
            simulation.render(robot)
        started = time.perf_counter()
        for _ in range(frames):
            for robot in robots:
                simulation.render(robot)
        render_ms = (time.perf_counter() - started) / frames * 1000
        started = time.perf_counter()
        for frame in range(frames):
            command(frame)
            simulation.step_frame()
        step_ms = (time.perf_counter() - started) / frames * 1000
        started, started_cpu = time.perf_counter(), time.process_time()
        for frame in range(frames):
            command(frame)
            simulation.step_frame()
            for robot in robots:
                simulation.render(robot)
                simulation.ground_truth(robot)
        loop_seconds = time.perf_counter() - started
        cpu_ms = (time.process_time() - started_cpu) / frames * 1000
    finally:
        simulation.close()
    return {"render_ms": render_ms, "step_ms": step_ms, "fast_fps": frames / loop_seconds,
            "fast_cpu_ms": cpu_ms}


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m balltrack.services.simulator.benchmark",
                            description="Benchmark the simulator core: "
                                        "python -m balltrack.services.simulator.benchmark --frames 150")
    parser.add_argument("--frames", type=integer(minimum=1), default=150, help="frames per measurement (default 150)")
    parser.add_argument("--config", default=None, help="a parameter file with a [simulator] section")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a parameter, repeatable")
    parser.add_argument("--robots", type=integer(minimum=0, maximum=64), nargs="+", default=None, metavar="N",
                        help="measure with each of these robot counts in turn (the `robots` setting; "
                             "e.g. --robots 1 2 4 8 16 --set scenario=fleet)")
    arguments = parser.parse_args(argv)
    try:
        settings = load_config(SimulatorConfig, arguments.config, arguments.set, section="simulator")
        runs = [settings] if arguments.robots is None else [
            replace_config(settings, {"robots": robots}) for robots in arguments.robots]
        for run in runs:
            run.preflight()  # (robots that do not fit the scenario: one line, before any render)
    except ConfigError as error:
        parser.error(str(error))
    for run in runs:
        results = benchmark(run, arguments.frames)
        print(f"{run.width}x{run.height} shadows={run.shadows} robots={run.robots}: "
              f"render {results['render_ms']:.1f} ms/frame, step {results['step_ms']:.2f} ms/frame, "
              f"fast mode (step + render + ground truth) {results['fast_fps']:.1f} frames/s, "
              f"{results['fast_cpu_ms']:.1f} ms CPU/frame", flush=True)
    return 0


if __name__ == "__main__":
    exit_with(main)
