"""A service stops cleanly (status 0, within a supervisor's 15 s before SIGKILL) while its router
is frozen (SIGSTOP: the connection stays open and nothing is read) with frames queued for it:
the simulator's teardown behind that backlog took 13 s over TCP and 20 s over TLS, until
common/runner.CLOSE_LIMIT_S cut it short."""

import os
import signal
import time

from tests.harness import Collector, Liveliness, start_service, wait_until

SUPERVISOR_STOP_TIMEOUT = 15.0  # deploy/supervisor.SupervisorSettings.stop_timeout


def test_the_simulator_stops_cleanly_while_its_router_is_frozen(router, session, log_dir):
    frames = Collector(session, "camera/image_raw", None)  # (someone the frames are sent to)
    simulator = start_service("simulator", router.endpoint, log_dir)
    try:
        Liveliness(session).wait("simulator", timeout=60)
        wait_until(lambda: len(frames.messages) >= 10, 30, "frames flowing", simulator)
        os.kill(router.process.popen.pid, signal.SIGSTOP)
        try:
            # (frozen once nothing more arrives; meanwhile the simulator's frames queue up)
            seen = [len(frames.messages), time.monotonic()]

            def quiet_for_a_second():
                if len(frames.messages) != seen[0]:
                    seen[:] = [len(frames.messages), time.monotonic()]
                return time.monotonic() - seen[1] >= 1.0

            wait_until(quiet_for_a_second, 20, "the frozen router's silence")
            status = simulator.stop(timeout=SUPERVISOR_STOP_TIMEOUT)
        finally:
            os.kill(router.process.popen.pid, signal.SIGCONT)
    finally:
        simulator.kill()
    output = simulator.output()
    assert status == 0 and "Traceback" not in output, output[-3000:]
