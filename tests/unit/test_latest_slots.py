"""The newest-only slots one worker serves several robots' frames from (common/latest.py)."""

import threading

from balltrack.common.latest import LatestSlots, Taken


def test_a_slot_keeps_the_newest_item_and_counts_what_arrived():
    slots = LatestSlots()
    for frame in range(5):
        slots.put("robot1", frame)
    assert slots.take(0) == Taken("robot1", 4, 5)
    assert slots.take(0) is None  # (emptied: the four older frames were dropped, not queued)


def test_full_slots_are_served_in_turn():
    slots = LatestSlots()
    for source in ("robot1", "robot2", "robot3"):
        slots.add(source)
    slots.put("robot2", "a")
    slots.put("robot3", "b")
    slots.put("robot1", "c")
    # In the order the sources were added, whatever order their items came in.
    assert [slots.take(0).source for _ in range(3)] == ["robot1", "robot2", "robot3"]


def test_a_flooding_source_gets_one_turn_in_as_many_as_are_waiting():
    slots = LatestSlots()
    served = []
    for turn in range(6):
        # robot1 floods: ten frames before each turn; robot2 and robot3 one each, every other turn
        for frame in range(10):
            slots.put("robot1", (turn, frame))
        if turn % 2 == 0:
            slots.put("robot2", turn)
            slots.put("robot3", turn)
        served.append(slots.take(0).source)
    assert served == ["robot1", "robot2", "robot3", "robot1", "robot2", "robot3"]


def test_the_turn_goes_on_from_the_source_served_last():
    slots = LatestSlots()
    slots.put("robot1", 1)
    slots.put("robot2", 1)
    assert slots.take(0).source == "robot1"
    slots.put("robot1", 2)
    # robot2 has waited since before robot1's second item: it goes first.
    assert [slots.take(0).source, slots.take(0).source] == ["robot2", "robot1"]


def test_take_waits_for_an_item_put_from_another_thread():
    slots = LatestSlots()
    taken = []
    worker = threading.Thread(target=lambda: taken.append(slots.take(10)))
    worker.start()
    slots.put("robot2", "frame")
    worker.join(10)
    assert taken == [Taken("robot2", "frame", 1)]


def test_close_ends_a_waiting_take_and_every_later_one():
    slots = LatestSlots()
    taken = []
    worker = threading.Thread(target=lambda: taken.append(slots.take()))
    worker.start()
    slots.close()
    worker.join(10)
    assert not worker.is_alive() and taken == [None]
    slots.put("robot1", "late")
    assert slots.take() is None and slots.closed
