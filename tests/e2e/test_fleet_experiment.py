"""``balltrack experiment fleet --quick``: every robot count started, measured and stopped on this
machine, ``fleet/max_robots`` written; the figures are checked for being a fleet's, not for the
machine's speed (a loaded machine serves fewer robots)."""

import json

import pytest

from balltrack.experiments import cli
from balltrack.experiments.fleet import ROBOT_COUNTS

pytestmark = pytest.mark.slow


def test_fleet_experiment_writes_max_robots_and_a_row_per_robot_count(tmp_path):
    assert cli.main(["fleet", "--quick", "--out", str(tmp_path), "--no-progress"]) == 0
    results = json.loads((tmp_path / "results.json").read_text())
    figures = results["figures"]
    assert figures["fleet/max_robots"] in (0, *ROBOT_COUNTS)
    for robots in ROBOT_COUNTS:
        prefix = f"fleet/robots_{robots}"
        assert figures[f"{prefix}/real_time_factor"] > 0
        assert figures[f"{prefix}/cpu_per_robot_second"] > 0
        assert figures[f"{prefix}/messages_per_s"] > 10 * robots  # frames, truths, clocks... of each robot
        for index in range(1, robots + 1):
            assert figures[f"{prefix}/robot{index}/positions"] > 0
    # One robot alone, 1.2 m from its ball, reaches it however loaded the machine.
    assert figures["fleet/robots_1/reached"] == 1
    assert {goal["name"] for goal in results["goals"]} == {"fleet/max_robots", "fleet/reached"}
    assert (tmp_path / "fleet.png").stat().st_size > 1000
