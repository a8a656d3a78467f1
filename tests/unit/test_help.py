"""Every command's ``--help`` prints its usage and exits 0: argparse formats help texts with
``%``, so a stray ``%`` in one (a variant named "specks 2%") breaks the whole page."""

import importlib
import importlib.util
from pathlib import Path

import pytest

COMMANDS = (
    "balltrack.cli", "balltrack.deploy.cli", "balltrack.deploy.demo",
    "balltrack.deploy.params", "balltrack.experiments.cli",
    "balltrack.experiments.detector_outputs", "balltrack.experiments.detector_speed",
    "balltrack.experiments.frame_transport", "balltrack.experiments.io_throughput",
    "balltrack.experiments.locator_table", "balltrack.experiments.real_photos",
    "balltrack.experiments.realtime_check", "balltrack.experiments.ros2_bridge_latency",
    "balltrack.experiments.viewer_cost", "balltrack.services.camera.service",
    "balltrack.services.detector.service", "balltrack.services.follower.service",
    "balltrack.services.locator.service", "balltrack.services.ros2_bridge.service",
    "balltrack.services.simulator.benchmark", "balltrack.services.simulator.service",
)


# The example stands alone (copied anywhere, balltrack not installed): loaded from its file.
EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "subscribe_ball3d.py"


def example_main():
    spec = importlib.util.spec_from_file_location("subscribe_ball3d", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main


@pytest.mark.parametrize("module", COMMANDS + ("examples/subscribe_ball3d.py",))
def test_help_exits_zero_with_usage(module, capsys):
    main = example_main() if module.endswith(".py") else importlib.import_module(module).main
    with pytest.raises(SystemExit) as exited:
        main(["--help"])
    assert exited.value.code in (0, None)
    assert "usage" in capsys.readouterr().out.lower()
