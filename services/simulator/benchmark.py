"""The simulator core's speed, without pacing or Zenoh: render-only and step-only ms per frame,
and frames per second of the fast mode (step, render and ground truth back to back).

Example::

    python -m balltrack.services.simulator.benchmark --frames 150 --set shadows=true
"""

import math
import time

from balltrack.common.arguments import ArgumentParser, integer
from balltrack.common.config import ConfigError, load_config
from balltrack.common.terminal import exit_with
from balltrack.services.simulator.config import SimulatorConfig
from balltrack.services.simulator.sim import Simulation


def benchmark(config: SimulatorConfig, frames: int = 150) -> dict[str, float]:
    """Time the frame loop without pacing: render-only ms/frame, step-only ms, fast-mode fps."""
    simulation = Simulation(config)
    try:
        simulation.render()  # warm-up: first render compiles shaders / uploads textures
        started = time.perf_counter()
        for _ in range(frames):
            simulation.render()
        render_ms = (time.perf_counter() - started) / frames * 1000
        started = time.perf_counter()
        for frame in range(frames):
            simulation.set_command(0.3, 0.5 * math.sin(frame / 10), simulation.time)
            simulation.step_frame()
        step_ms = (time.perf_counter() - started) / frames * 1000
        started = time.perf_counter()
        for frame in range(frames):
            simulation.set_command(0.3, 0.5 * math.sin(frame / 10), simulation.time)
            simulation.step_frame()
            simulation.render()
            simulation.ground_truth()
        loop_seconds = time.perf_counter() - started
    finally:
        simulation.close()
    return {"render_ms": render_ms, "step_ms": step_ms, "fast_fps": frames / loop_seconds}


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m balltrack.services.simulator.benchmark",
                            description="Benchmark the simulator core: "
                                        "python -m balltrack.services.simulator.benchmark --frames 150")
    parser.add_argument("--frames", type=integer(minimum=1), default=150, help="frames per measurement (default 150)")
    parser.add_argument("--config", default=None, help="a parameter file with a [simulator] section")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a parameter, repeatable")
    arguments = parser.parse_args(argv)
    try:
        settings = load_config(SimulatorConfig, arguments.config, arguments.set, section="simulator")
    except ConfigError as error:
        parser.error(str(error))
    results = benchmark(settings, arguments.frames)
    print(f"{settings.width}x{settings.height} shadows={settings.shadows}: "
          f"render {results['render_ms']:.1f} ms/frame, step {results['step_ms']:.2f} ms/frame, "
          f"fast mode (step + render + ground truth) {results['fast_fps']:.1f} frames/s")
    return 0


if __name__ == "__main__":
    exit_with(main)
