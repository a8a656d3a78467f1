"""The follower as a real process: detections in, cmd_vel out, on wall and simulated time."""

import pytest

from balltrack.common.messages import encode, header
from tests.harness import Collector, garbage_payloads, put_until, query_config


def detection(x, z, seq):
    return {"header": header(seq * 1000, seq), "x": x, "y": 0.0, "z": z, "u": 320 + 320 * x,
            "v": 240.0, "radius_px": z * 320, "image_width": 640, "image_height": 480, "score": 1.0}


@pytest.fixture
def start_follower(launch):
    # These tests drive the paper's input, detected_ball; target keeping has its own test.
    return lambda *overrides: launch("follower", "keep_target=false", *overrides)


def test_chase_arrive_then_search_on_wall_time(session, start_follower):
    start_follower("rcv_timeout_secs=0.5")
    commands = Collector(session, "cmd_vel", "Twist")
    commands.wait_for(lambda m: m and m[-1]["mode"] == "search", 5, "search before any ball")
    assert commands.messages[-1]["angular"][2] == pytest.approx(0.5)

    session.put("detected_ball", encode("Ball2D", detection(0.4, 0.05, 1)))
    chase = commands.wait_for(lambda m: [c for c in m if c["header"]["seq"] == 1], 5, "chase")[0]
    # The first detection restarts the filter, so the command uses x itself: -0.7 * 0.4.
    assert chase["angular"][2] == pytest.approx(-0.28)
    assert chase["linear"][0] == pytest.approx(0.1)
    assert chase["header"]["stamp"] == 1000  # capture time travels with the command

    session.put("detected_ball", encode("Ball2D", detection(0.2, 0.5, 2)))
    arrived = commands.wait_for(lambda m: [c for c in m if c["header"]["seq"] == 2], 5, "update")[0]
    # Filtered size 0.9 * 0.05 + 0.1 * 0.5 = 0.095 < 0.1: still driving; x filtered to 0.38.
    assert arrived["linear"][0] == pytest.approx(0.1)
    assert arrived["angular"][2] == pytest.approx(-0.7 * 0.38)

    lost = commands.wait_for(lambda m: [c for c in m if c["mode"] == "search" and
                                        c["header"]["seq"] == 2], 5, "search after timeout")[0]
    assert lost["linear"][0] == 0.0
    # Last seen on the right (x > 0), so the search spins clockwise toward it.
    assert lost["angular"][2] == pytest.approx(-0.5)


def test_sim_time_drives_timer_and_timeout(session, start_follower):
    start_follower("use_sim_time=true", "rcv_timeout_secs=1.0")
    commands = Collector(session, "cmd_vel", "Twist")

    def advance_to(seconds):
        session.put("clock", encode("Clock", {"stamp": int(seconds * 1e9)}))

    advance_to(1.0)
    commands.wait_for(lambda m: m, 10, "first tick on simulated time")
    session.put("detected_ball", encode("Ball2D", detection(-0.2, 0.05, 5)))
    # Time stands still in simulation until the clock moves: no tick without a clock message.
    step = 1.0
    while not [c for c in commands.messages if c["header"]["seq"] == 5 and c["mode"] == "chase"]:
        step += 0.1
        advance_to(step)
        commands.wait_for(lambda m, n=len(commands.messages): len(m) > n, 5, "tick")
        assert step < 1.5, "no chase command after the detection"
    advance_to(step + 0.5)   # 0.5 s of simulated time later: still fresh
    fresh = commands.wait_for(lambda m: [c for c in m if c["header"]["stamp"] == 5000], 5, "fresh")
    assert fresh[-1]["mode"] == "chase"
    advance_to(step + 1.3)   # now older than rcv_timeout_secs in simulated time
    commands.wait_for(lambda m: m[-1]["mode"] == "search" and
                      m[-1]["header"]["stamp"] == int((step + 1.3) * 1e9), 5, "search on sim time")


def test_bad_input_config_and_clean_exit(session, start_follower):
    start_follower()
    commands = Collector(session, "cmd_vel", "Twist")
    stats = Collector(session, "follower/stats", "Stats")
    cases = garbage_payloads(detection(0.1, 0.05, 1))
    for _, payload in cases:
        session.put("detected_ball", payload)
    session.put("detected_ball", encode("Ball2D", detection(0.5, 0.05, 9)))
    chase = commands.wait_for(lambda m: [c for c in m if c["header"]["seq"] == 9], 5, "good after bad")
    assert chase[0]["angular"][2] == pytest.approx(-0.35)
    stats.wait_for(lambda m: m and m[-1]["rejected"] >= len(cases), 5, "rejections")

    assert query_config(session, "follower", {"angular_chase_multiplier": 2.0})["ok"]
    session.put("detected_ball", encode("Ball2D", detection(0.5, 0.05, 10)))
    commands.wait_for(lambda m: [c for c in m if c["header"]["seq"] == 10 and
                                 c["angular"][2] == pytest.approx(-1.0)], 5, "new gain")
    reply = query_config(session, "follower", {"filter_value": 1.5})
    assert not reply["ok"] and reply["error"].startswith("filter_value")
    assert not query_config(session, "follower", {"use_sim_time": True})["ok"]


def test_keeps_its_target_among_several_balls(session, start_follower):
    start_follower("keep_target=true")
    commands = Collector(session, "cmd_vel", "Twist")

    def frame(seq, *balls):
        return encode("Ball2DArray", {"header": header(seq * 1000, seq), "balls": [
            {key: value for key, value in detection(x, z, seq).items() if key != "header"}
            for x, z in balls]})

    session.put("detected_balls", frame(1, (0.4, 0.05)))
    commands.wait_for(lambda m: [c for c in m if c["header"]["seq"] == 1], 5, "chase")
    # A larger ball appears on the other side; the target is still there: keep turning right.
    session.put("detected_balls", frame(2, (-0.5, 0.09), (0.38, 0.05)))
    command = commands.wait_for(lambda m: [c for c in m if c["header"]["seq"] == 2], 5, "kept")[-1]
    assert command["angular"][2] < 0
    assert command["angular"][2] == pytest.approx(-0.7 * (0.9 * 0.4 + 0.1 * 0.38))


def test_command_on_detection_answers_every_frame_at_once(session, start_follower):
    # A long timer period: the timer's commands (with ``time``) are few, the event ones are not.
    start_follower("keep_target=true", "command_on_detection=true", "rate_hz=1")
    commands = Collector(session, "cmd_vel", "Twist")

    def frame(seq, *balls):
        return encode("Ball2DArray", {"header": header(seq * 1000, seq), "balls": [
            {key: value for key, value in detection(x, z, seq).items() if key != "header"}
            for x, z in balls]})

    def events(messages):
        return [command for command in messages if "time" not in command]

    sent = list(range(1, 11))
    for seq in sent:
        # Frame 6 has no ball: it is answered too, with the held command.
        session.put("detected_balls", frame(seq) if seq == 6 else frame(seq, (0.4, 0.05)))
        commands.wait_for(lambda m, seq=seq: [c for c in events(m) if c["header"]["seq"] == seq], 5,
                          f"command for frame {seq}")
    answered = events(commands.messages)
    assert [command["header"]["seq"] for command in answered] == sent
    assert [command["header"]["stamp"] for command in answered] == [seq * 1000 for seq in sent]
    assert {command["mode"] for command in answered} == {"chase"}
    assert answered[0]["angular"][2] == pytest.approx(-0.28)
    # The timer still runs as the watchdog, and its ticks alone carry ``time``.
    ticks = commands.wait_for(lambda m: [c for c in m if "time" in c and c["mode"] == "search"
                                         and c["header"]["seq"] == 10], 10, "search after the frames stop")
    assert ticks[-1]["angular"][2] == pytest.approx(-0.5)


def test_switching_keep_target_live_follows_the_other_key(session, start_follower):
    # Only the key in use is subscribed: the switch must declare the other one.
    start_follower("command_on_detection=true", "rate_hz=1")
    commands = Collector(session, "cmd_vel", "Twist")

    def answered(seq):
        return lambda messages: [c for c in messages if "time" not in c and c["header"]["seq"] == seq]

    put_until(lambda _: session.put("detected_ball", encode("Ball2D", detection(0.4, 0.05, 1))),
              commands, answered(1), 10, 0.5, "a command for detected_ball")
    assert query_config(session, "follower", {"keep_target": True})["ok"]
    sent = iter(range(2, 1000))

    def put_frame(_):
        seq = next(sent)
        session.put("detected_ball", encode("Ball2D", detection(0.4, 0.05, seq)))
        session.put("detected_balls", encode("Ball2DArray", {"header": header(seq * 1000, seq), "balls": [
            {key: value for key, value in detection(0.4, 0.05, seq).items() if key != "header"}]}))

    put_until(put_frame, commands, lambda messages: [c for c in messages if "time" not in c
                                                     and c["header"]["seq"] >= 2], 10, 0.5,
              "a command for detected_balls after the switch")
    assert query_config(session, "follower", {"keep_target": False})["ok"]
    put_until(lambda _: session.put("detected_ball", encode("Ball2D", detection(0.4, 0.05, 2000))),
              commands, answered(2000), 10, 0.5, "a command for detected_ball after switching back")


def test_commands_stay_on_the_frame_clock_while_chasing_and_searching(session, start_follower):
    # `deploy start`'s defaults: the follower's timer on the wall clock, the frames on a
    # simulator's (seconds from its start). Every command must carry the frames' clock.
    start_follower("keep_target=true", "rcv_timeout_secs=0.5")
    commands = Collector(session, "cmd_vel", "Twist")
    commands.wait_for(lambda m: m and m[-1]["mode"] == "search", 5, "search before any frame")
    sent = {0: 0}  # stamp -> seq of every frame put; 0 is the stamp before any frame
    frames = iter(range(1, 10_000))

    def put_frame(*balls):
        seq = next(frames)
        stamp = 3_000_000_000 + seq * 33_333_333
        sent[stamp] = seq
        session.put("detected_balls", encode("Ball2DArray", {"header": header(stamp, seq), "balls": [
            {key: value for key, value in detection(x, z, seq).items() if key != "header"}
            for x, z in balls]}))

    put_until(lambda _: put_frame((0.4, 0.05)), commands,
              lambda m: [c for c in m if c["mode"] == "chase"], 10, 0.2, "a chase command")
    last_chase_frame = max(sent)
    # Frames without the ball: after rcv_timeout_secs the follower searches.
    put_until(lambda _: put_frame(), commands, lambda m: [
        c for c in m if c["mode"] == "search" and c["header"]["stamp"] > last_chase_frame],
        10, 0.2, "a search command after frames without the ball")
    # No frames at all: the search goes on with the last frame's stamp.
    seen = len(commands.messages)
    commands.wait_for(lambda m: len(m) >= seen + 3, 5, "search commands after the frames stopped")

    for command in list(commands.messages):
        assert command["header"]["stamp"] in sent, command
        assert sent[command["header"]["stamp"]] == command["header"]["seq"], command
        assert command["time"] in sent, command
    assert {command["mode"] for command in commands.messages} == {"chase", "search"}
    last_frame = max(sent)
    assert commands.messages[-1]["header"]["stamp"] == commands.messages[-1]["time"] == last_frame
