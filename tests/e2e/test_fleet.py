"""A simulated fleet chasing its balls end to end: one simulator holding three robots in the
``fleet`` scenario (lockstep, 320x240, 15 Hz) and one process serving every robot's detector,
locator and follower (``--namespaces auto``, which finds the robots by their frame source's
liveliness token), over a real router; each robot judged on ground truth by its own referee."""

import pytest

from balltrack.common.referee import Referee
from balltrack.services.simulator.fleet import own_ball_id, own_ball_referees
from tests.harness import Collector, Liveliness, start_service

pytestmark = pytest.mark.slow

ROBOTS = 3
SIMULATED_SECONDS = 25.0


def test_every_robot_of_the_fleet_reaches_its_own_ball(router, session, log_dir):
    truths = {name: Collector(session, f"{name}/sim/ground_truth", "GroundTruth")
              for name in own_ball_referees(ROBOTS)}
    pipeline = start_service("detector+locator+follower", router.endpoint, log_dir, "--namespaces", "auto",
                             "--set", "follower.use_sim_time=true", "--set", "follower.max_size_thresh=0.3")
    simulator = start_service("simulator", router.endpoint, log_dir, "--set", "scenario=fleet",
                              "--set", f"robots={ROBOTS}", "--set", "pacing=lockstep", "--set", "width=320",
                              "--set", "height=240", "--set", "rate_hz=15", "--set", "lockstep_timeout=10")
    try:
        for name in truths:  # served as found
            Liveliness(session, name).wait("follower", timeout=60)
        for collector in truths.values():
            collector.wait_for(lambda messages: messages and messages[-1]["header"]["stamp"] >= SIMULATED_SECONDS * 1e9,
                               300, f"{SIMULATED_SECONDS} simulated seconds")
    finally:
        codes = [process.stop() for process in (simulator, pipeline)]
    assert codes == [0, 0], simulator.output() + pipeline.output()
    assert " 0 lockstep timeouts" in simulator.output(), simulator.output()
    referees = own_ball_referees(ROBOTS, time_limit=SIMULATED_SECONDS - 2)
    for index, (name, collector) in enumerate(truths.items()):
        neighbours = Referee(target=own_ball_id((index + 1) % ROBOTS + 1))
        for truth in collector.messages:
            referees[name].update(truth["header"]["stamp"] / 1e9, truth)
            neighbours.update(truth["header"]["stamp"] / 1e9, truth)
        assert not neighbours.reached, f"{name} reached {neighbours.target}"
    verdicts = {name: (referee.reached_at, round(referee.closest, 2)) for name, referee in referees.items()}
    assert all(referee.reached for referee in referees.values()), verdicts
