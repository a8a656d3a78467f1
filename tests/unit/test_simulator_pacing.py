"""The simulator service's pacing helpers: realtime deadlines, timer ticks, lockstep waits."""

import math
import threading

import pytest

from balltrack.common.clock import TimerTicks
from balltrack.services.simulator.pacing import LockstepGate, RateMeter, RealtimePacer, WorkEstimate

PERIOD = 1 / 30


def test_realtime_deadlines_follow_sim_time_and_never_burst():
    pacer = RealtimePacer()
    assert pacer.delay(PERIOD, 1.0, PERIOD, now=100.0) == 0.0  # the first frame anchors
    assert pacer.delay(2 * PERIOD, 1.0, PERIOD, now=100.01) == pytest.approx(PERIOD - 0.01)
    # Twice as fast: the next frame is due half a period after the anchor.
    pacer.reset()
    pacer.delay(PERIOD, 2.0, PERIOD, now=200.0)
    assert pacer.delay(2 * PERIOD, 2.0, PERIOD, now=200.0) == pytest.approx(PERIOD / 2)
    # Late by less than a frame: due now, the schedule is kept (the next one catches up).
    pacer.reset()
    pacer.delay(PERIOD, 1.0, PERIOD, now=300.0)
    assert pacer.delay(2 * PERIOD, 1.0, PERIOD, now=300.0 + 1.5 * PERIOD) == 0.0
    assert pacer.delay(3 * PERIOD, 1.0, PERIOD, now=300.0 + 1.6 * PERIOD) == pytest.approx(0.4 * PERIOD)
    assert pacer.slips == 0
    # Late by more than a frame: a slip, and the schedule restarts from now (no burst).
    assert pacer.delay(4 * PERIOD, 1.0, PERIOD, now=300.0 + 10 * PERIOD) == 0.0
    assert pacer.slips == 1
    assert pacer.delay(5 * PERIOD, 1.0, PERIOD, now=300.0 + 10 * PERIOD) == pytest.approx(PERIOD)


def test_a_frame_is_started_its_lead_before_it_is_due_without_touching_the_schedule():
    pacer = RealtimePacer()
    assert pacer.start_delay(PERIOD, 1.0, now=100.0, lead=0.01) == 0.0  # no schedule yet
    pacer.delay(PERIOD, 1.0, PERIOD, now=100.0)
    # Frame 2 is due at 100 + PERIOD; made in 10 ms, it is started 10 ms before that.
    assert pacer.start_delay(2 * PERIOD, 1.0, now=100.0, lead=0.01) == pytest.approx(PERIOD - 0.01)
    assert pacer.start_delay(2 * PERIOD, 2.0, now=100.0, lead=0.01) == 0.0  # the rate changed
    # Already within the lead, or late: start at once, and neither a slip nor a new anchor.
    assert pacer.start_delay(2 * PERIOD, 1.0, now=100.0 + 5 * PERIOD, lead=0.01) == 0.0
    assert pacer.slips == 0
    assert pacer.delay(2 * PERIOD, 1.0, PERIOD, now=100.0) == pytest.approx(PERIOD)


def test_the_lead_is_a_high_percentile_of_recent_work_plus_a_margin():
    estimate = WorkEstimate(window=10, quantile=0.9, margin=0.002)
    assert estimate.lead() == pytest.approx(0.002)
    for milliseconds in (5, 6, 7, 8, 9, 10, 11, 12, 13, 30):
        estimate.add(milliseconds / 1000)
    assert estimate.lead() == pytest.approx(0.030 + 0.002)  # the 90th percentile of 10 is the top
    for _ in range(10):  # the window forgets a slow start (the first renders compile shaders)
        estimate.add(0.008)
    assert estimate.lead() == pytest.approx(0.010)


def test_timer_ticks_fire_on_the_first_clock_then_on_crossing_multiples():
    ticks = TimerTicks()
    fired = [frame for frame in range(1, 31) if ticks.fires(round(frame * PERIOD * 1e9), 0.1)]
    assert fired[0] == 1
    # Then one tick exactly on each multiple of 0.1 s (every third frame at 30 Hz).
    assert fired == [1] + list(range(3, 31, 3))
    assert not ticks.fires(round(30 * PERIOD * 1e9), 0.1)  # the same clock again
    assert ticks.fires(round(2 * PERIOD * 1e9), 0.1)      # the clock went back: a new timer


def test_lockstep_gate_waits_for_the_answer_or_times_out():
    stop = threading.Event()
    gate = LockstepGate(stop)
    assert gate.wait_answer(5, timeout=0.0)  # no detector alive: nothing to wait for
    gate.set_alive("detector", True)
    assert not gate.wait_answer(5, timeout=0.05) and gate.timeouts == 1
    answer = threading.Timer(0.01, gate.answered, (5,))
    answer.start()
    assert gate.wait_answer(5, timeout=10)
    answer.join()
    leave = threading.Timer(0.01, gate.set_alive, ("detector", False))
    leave.start()
    assert gate.wait_answer(6, timeout=10)  # the detector went away: no need to wait
    leave.join()
    assert gate.timeouts == 1


def test_a_lockstep_timeout_shortened_during_a_wait_ends_it():
    gate = LockstepGate(threading.Event())
    gate.set_alive("detector", True)
    timeout = {"seconds": 60.0}
    ended = []
    waiter = threading.Thread(target=lambda: ended.append(gate.wait_answer(5, lambda: timeout["seconds"])))
    waiter.start()
    timeout["seconds"] = 0.05  # (lockstep_timeout changed live while the frame waits)
    waiter.join(10)
    assert not waiter.is_alive(), "the wait ran on to its old 60 s timeout"
    assert ended == [False] and gate.timeouts == 1


def test_lockstep_gate_follower_ticks_restart_with_a_new_follower():
    gate = LockstepGate(threading.Event())
    assert not gate.follower_fires(33_333_333, 0.1)  # no follower
    gate.set_alive("follower", True)
    assert gate.follower_fires(66_666_667, 0.1)      # its first clock
    assert not gate.follower_fires(100_000_000 - 2_000, 0.1)  # beyond the 1 us tolerance
    assert gate.follower_fires(100_000_000, 0.1)
    gate.set_alive("follower", False)
    gate.set_alive("follower", True)                  # restarted between two clocks
    assert gate.follower_fires(133_333_333, 0.1)
    gate.commanded(133_333_333)
    assert gate.wait_command(133_333_333, timeout=0.0)


def test_rate_meter_reports_sim_seconds_per_wall_second():
    meter = RateMeter(window=5.0)
    assert meter.factor() == 0.0
    for frame in range(200):
        meter.add(frame * 0.05, frame * PERIOD)  # 30 Hz frames every 50 ms of wall time
    assert meter.factor() == pytest.approx(PERIOD / 0.05)
    assert meter.frames_per_second() == pytest.approx(20.0)
    assert math.isclose(meter.factor(), 2 / 3, rel_tol=1e-9)
