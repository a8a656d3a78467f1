"""The clock a follower's command carries: the frames', while chasing and while searching."""

from balltrack.common.messages import header
from balltrack.services.follower.stamping import CommandStamps, Stamp

# Frame stamps as a simulator makes them: simulated time, far from the wall clock's 1.7e18 ns.
FRAME_1 = header(2_000_000_000, 60)
FRAME_2 = header(2_033_333_333, 61)
FRAME_3 = header(2_066_666_667, 62)


def test_before_any_frame_a_search_carries_zero():
    assert CommandStamps().for_tick(searching=True, sim_clock_ns=None) == Stamp(0, 0, 0)


def test_chasing_on_the_wall_clock_carries_the_followed_frame_and_its_clock():
    stamps = CommandStamps()
    stamps.saw_frame(FRAME_1)
    stamps.follow(FRAME_1)
    assert stamps.for_tick(searching=False, sim_clock_ns=None) == Stamp(FRAME_1["stamp"], 60, FRAME_1["stamp"])
    # A frame without the target is seen, the target is still held: the header stays the
    # followed detection's, ``time`` moves on with the frames.
    stamps.saw_frame(FRAME_2)
    assert stamps.for_tick(searching=False, sim_clock_ns=None) == Stamp(FRAME_1["stamp"], 60, FRAME_2["stamp"])


def test_searching_on_the_wall_clock_carries_the_last_frame_seen():
    stamps = CommandStamps()
    stamps.saw_frame(FRAME_1)
    stamps.follow(FRAME_1)
    stamps.saw_frame(FRAME_2)
    stamps.saw_frame(FRAME_3)
    assert stamps.for_tick(searching=True, sim_clock_ns=None) == Stamp(FRAME_3["stamp"], 62, FRAME_3["stamp"])
    # No more frames: the search goes on with the last one's stamp, never the wall clock's.
    assert stamps.for_tick(searching=True, sim_clock_ns=None) == Stamp(FRAME_3["stamp"], 62, FRAME_3["stamp"])


def test_on_simulated_time_the_tick_carries_the_clock_that_fired_it():
    stamps = CommandStamps()
    assert stamps.for_tick(searching=True, sim_clock_ns=1_900_000_000) == Stamp(1_900_000_000, 0, 1_900_000_000)
    stamps.saw_frame(FRAME_1)
    stamps.follow(FRAME_1)
    assert stamps.for_tick(searching=False, sim_clock_ns=2_000_000_000) == Stamp(FRAME_1["stamp"], 60, 2_000_000_000)
    assert stamps.for_tick(searching=True, sim_clock_ns=3_100_000_000) == Stamp(3_100_000_000, 60, 3_100_000_000)
