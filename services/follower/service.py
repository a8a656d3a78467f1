"""Follower service: ``detected_ball`` -> ``cmd_vel`` (paper section 2.4, ROS2 follow_ball).

Subscribes: ``detected_balls`` (Ball2DArray) to keep one target among several balls
(``keep_target``, default), or instead ``detected_ball`` (Ball2D, the largest) as the original
node does (``keep_target=false``; switching it live swaps the subscription); ``clock`` (Clock)
when ``use_sim_time`` is set.
Publishes: ``cmd_vel`` (Twist) from a ``rate_hz`` timer (10 Hz) on the configured clock, stamped
on the frames' clock whatever that is (services/follower/stamping.py): while tracking, the header
is the followed detection's (so latency from frame capture to command can be measured); while
searching, the last detection message's; ``time`` is the frame clock at the tick. With
``command_on_detection`` a command is also published from each detection message's callback, at
once, with that message's header and without the ``time`` field, so a lockstep simulator still
paces on the timer's ticks.

Example:
    balltrack run follower --connect tcp/127.0.0.1:7447 --set max_size_thresh=0.3 --set use_sim_time=true
"""

import threading

from balltrack.common import keys
from balltrack.common.messages import MessageError
from balltrack.common.context import ServiceContext
from balltrack.common.runner import run_service
from balltrack.services.follower.config import FollowerConfig
from balltrack.services.follower.controller import SEARCH, FollowerController
from balltrack.services.follower.stamping import CommandStamps


def build(service: ServiceContext):
    output = service.publisher(keys.CMD_VEL, "Twist")
    controller = FollowerController(service.config)
    lock = threading.Lock()  # detections and the timer run on different threads
    stamps = CommandStamps()
    service.on_config_change(lambda config: controller.update_config(config))

    def publish(command, header: dict, tick_ns: int | None) -> None:
        # Only the contract's header fields travel on: whatever else a peer put into the
        # detection's header must not be repeated in every command (ten times a second).
        # ``time`` (the frame clock at this tick) and ``mode`` are fields added to the contract's
        # Twist: a lockstep simulator waits for the tick stamped with its frame time, so a
        # command sent on a detection carries no ``time``.
        message = {"header": {"stamp": header["stamp"], "frame_id": "base_link", "seq": header["seq"]},
                   "mode": command.mode,
                   "linear": [command.linear, 0.0, 0.0], "angular": [0.0, 0.0, command.angular]}
        if tick_ns is not None:
            message["time"] = tick_ns
        output.put(message)

    def command_now(frame_header: dict) -> None:
        """With ``command_on_detection``: answer this detection message at once (under the lock)."""
        if service.config.command_on_detection:
            publish(controller.tick(service.clock.now()), frame_header, None)

    def on_ball(ball: dict) -> None:
        if service.config.keep_target:
            return
        with lock:
            if not controller.on_detection(ball["x"], ball["z"], service.clock.now()):
                raise MessageError("detection ignored: x or z out of range")
            stamps.saw_frame(ball["header"])
            stamps.follow(ball["header"])
            command_now(ball["header"])

    def on_balls(frame: dict) -> None:
        if not service.config.keep_target:
            return
        with lock:
            now = service.clock.now()
            stamps.saw_frame(frame["header"])
            target = controller.choose(frame["balls"], now)
            if target is not None and controller.on_detection(target["x"], target["z"], now):
                stamps.follow(frame["header"])
            # Every frame is answered, with or without the target in it: a follower of the
            # frames, one command each, whose mode says what the controller made of it.
            command_now(frame["header"])

    def tick() -> None:
        with lock:
            # Read the clock under the lock: a detection stamped after this tick's time would
            # look like the clock going back (a reset) and cost one spurious search command.
            now_ns = service.clock.now_ns()
            command = controller.tick(now_ns / 1e9)
            stamp = stamps.for_tick(command.mode == SEARCH, now_ns if service.clock.is_sim else None)
        publish(command, {"stamp": stamp.stamp, "seq": stamp.seq}, stamp.time)

    # Only the key in use is subscribed: the other is published on every frame too, and
    # decoding it for nothing cost the frame's command ~0.1 ms in the demo (it came first).
    # A change of keep_target swaps them, the new one declared before the old one goes.
    followed = {"key": None, "subscriber": None}

    def follow(config: FollowerConfig) -> None:
        key, message, handler = ((keys.DETECTED_BALLS, "Ball2DArray", on_balls) if config.keep_target
                                 else (keys.DETECTED_BALL, "Ball2D", on_ball))
        if key == followed["key"]:
            return
        previous = followed["subscriber"]
        followed.update(key=key, subscriber=service.subscribe(key, message, handler))
        if previous is not None:
            service.unsubscribe(previous)

    follow(service.config)
    service.on_config_change(follow)
    service.every(lambda: 1.0 / service.config.rate_hz, tick)
    return None


# The service's parameters (``balltrack run follower --help`` lists them); ``build`` wires it.
CONFIG = FollowerConfig


def main(argv=None) -> int:
    return run_service("follower", CONFIG, build, argv, __doc__)
