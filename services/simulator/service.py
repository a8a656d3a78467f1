"""Simulator service: the MuJoCo world as camera, robot base and referee (the paper's Gazebo).

Publishes every frame: ``camera/image_raw`` (Image, ``encoding`` bgr8 by default; header stamp =
simulated time, seq = frame index, frame_id "camera"), ``sim/ground_truth`` (GroundTruth, same
header), ``clock`` (Clock); ``camera/camera_info`` (CameraInfo) once per simulated second.
Subscribes: ``cmd_vel`` (Twist: linear[0] m/s, angular[2] rad/s, applied before the next step;
the safety stop zeroes it after ``cmd_timeout`` simulated seconds without one); for lockstep,
``detected_balls`` and the liveliness tokens ``alive/*``. Queries: ``camera/camera_info`` ->
CameraInfo; ``sim/control``: SimCommand -> SimReply (client: services/simulator/control.py).
Stats add ``real_time_factor``, ``render_ms``, ``lockstep_timeouts``, ``frames``,
``command_stamp`` (the simulated time, integer ns as every time on the network, at which the
last cmd_vel was taken; ``command_time``, the same in float seconds, stays for readers of the
field it was first); ``dropped`` counts realtime
schedule slips (overload). ``pacing``, ``real_time_factor``, ``lockstep_*``, ``encoding``,
``jpeg_quality`` and ``publish_images`` (false: no more frames, as from a failed camera; the
world, clock and ground truth go on) may be changed live through ``simulator/config``. With
``clock_file`` a simulator started again goes on with its predecessor's clock and frame numbers
(services/simulator/clock_file.py).

Lockstep, per frame k: image_raw + ground_truth; wait for ``detected_balls`` seq k (if a
detector is alive and the image was published); clock; if a follower is alive and its
simulated-time timer fires on this clock, wait for its cmd_vel whose added ``time`` field
equals this stamp; step. Each wait gives up after ``lockstep_timeout`` wall seconds (counted),
so the same seed gives the same run.

Several robots (``robots`` = N >= 1, services/simulator/fleet.py): robot K's keys are all of the
above under ``robotK/`` (``robotK/cmd_vel``, ``robotK/camera/image_raw``, ``robotK/clock``,
``robotK/sim/control``, the liveliness token ``robotK/alive/simulator``...; its ground truth
holds its pose and every ball); every robot's frame k has seq k. ``robotK/sim/control``'s ``place_robot`` moves robot K, its other ops the shared
world. In lockstep a frame waits for the detector of every robot with one alive
(``robotK/alive/detector``) and a tick for the follower of every robot whose timer fires, all
of one frame's waits within one ``lockstep_timeout``.

Example:
    balltrack run simulator --set scenario=chase --set pacing=lockstep --set seed=3
"""

import collections
import functools
import math
import threading
import time
from dataclasses import dataclass
from typing import Callable

import cv2
import zenoh

from balltrack.common import keys
from balltrack.common.clock import wait_out
from balltrack.common.images import bgr_to_message
from balltrack.common.config import ConfigError
from balltrack.common.memory import keep_freed_memory
from balltrack.common.messages import MessageError, decode, encode, header, shorten
from balltrack.common.context import Publisher, ServiceContext
from balltrack.common.runner import run_service
from balltrack.common.status import liveliness_keys
from balltrack.services.simulator.config import LIVE_SETTINGS, SimulatorConfig
from balltrack.services.simulator.fleet import robot_key, robot_names
from balltrack.services.simulator.pacing import LockstepGate, RateMeter, RealtimePacer, WorkEstimate, wait_together
from balltrack.services.simulator.requests import requested_scenario
from balltrack.services.simulator.scenario import SCENARIO_DIR, scenario_path
from balltrack.services.simulator.clock_file import ClockFile
from balltrack.services.simulator.output_files import OutputFiles
from balltrack.services.simulator.sim import ABSURD_ANGULAR, ABSURD_LINEAR, Simulation


def image_message(rgb, head: dict, config: SimulatorConfig) -> dict:
    """The Image message of a rendered RGB frame in the configured encoding."""
    if config.encoding == "rgb8":
        return {"header": head, "width": rgb.shape[1], "height": rgb.shape[0], "encoding": "rgb8",
                "data": rgb.tobytes()}
    return bgr_to_message(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), head["stamp"], head["seq"],
                          head["frame_id"], config.encoding, config.jpeg_quality)


def scenario_folder(configured: str):
    """The folder whose scenario files ``sim/control`` may load by name besides the shipped
    ones: that of the scenario file the simulator was started with (None for a shipped name)."""
    folder = scenario_path(configured).resolve().parent
    return None if folder == SCENARIO_DIR.resolve() else folder


@dataclass
class RobotLinks:
    """One robot's keys: what the simulator publishes for it, and the lockstep gate of the
    pipeline that answers it (services/simulator/fleet.py names the keys)."""

    index: int
    name: str
    images: Publisher
    truths: Publisher
    clocks: Publisher
    infos: Publisher
    gate: LockstepGate

    def key(self, key: str) -> str:
        """``key`` of this robot, under the service's namespace: ``robot2/cmd_vel``."""
        return robot_key(self.name, key)

    @classmethod
    def declare(cls, service: ServiceContext, index: int, name: str) -> "RobotLinks":
        # Lockstep must not lose a frame (it would wait for an answer that cannot come).
        block = {"congestion_control": zenoh.CongestionControl.BLOCK}
        lockstep = block if service.config.pacing == "lockstep" else {}
        return cls(index=index, name=name,
                   images=service.publisher(robot_key(name, keys.IMAGE_RAW), "Image", **lockstep),
                   truths=service.publisher(robot_key(name, keys.GROUND_TRUTH), "GroundTruth", **block),
                   clocks=service.publisher(robot_key(name, keys.CLOCK), "Clock", **block),
                   infos=service.publisher(robot_key(name, keys.CAMERA_INFO), "CameraInfo", **block),
                   gate=LockstepGate(service.stop))


def build(service: ServiceContext):
    output_files = OutputFiles.from_config(service.config)
    clock_file = ClockFile(service.config.clock_file) if service.config.clock_file else None
    start_stamp, start_frame = 0, 0
    if clock_file is not None:
        try:
            start_stamp, start_frame = clock_file.start()
        except ValueError as error:  # (a simulator that cannot start would be no better)
            service.log.warning("%s: the clock starts from 0", error)
    simulation = Simulation(service.config, start_time=start_stamp / 1e9, start_frame=start_frame)
    if start_stamp or start_frame:
        service.log.info("clock goes on from %s: %.3f s, frame %d", clock_file.path, simulation.time,
                         start_frame)
    simulation.render_view("front")  # the first render compiles shaders: not in frame 1's time
    # Each frame's message is a new megabyte: kept, not faulted in again (common/memory.py).
    keep_freed_memory()
    links = [RobotLinks.declare(service, index, name)
             for index, name in enumerate(robot_names(service.config.robots, service.config.first_robot))]
    if service.config.robots:
        # Each robot's namespace has its frame source alive, as a robot with its own camera
        # would: how a process serving many robots finds them (`--namespaces auto`).
        for link in links:
            service.declare(service.session.liveliness().declare_token(
                service.keys(link.key(keys.alive_key(service.name)))))
    meter, pacer, work = RateMeter(), RealtimePacer(), WorkEstimate()
    render_seconds, timing = collections.deque(maxlen=100), {"render_ms": 0.0}
    # (in a fleet, every robot's: robot1/alive/detector...)
    alive_keys = service.keys(robot_key("*" if service.config.robots else "", "alive/*"))
    links_by_name = {link.name: link for link in links}
    # Held from step to ground truth, so that no sim/control query lands between a frame's
    # image and its ground truth (the core locks each call, not the sequence).
    frame_lock = threading.Lock()
    pending = collections.deque()  # valid cmd_vel (robot, linear, angular), applied before a step

    clock_file_error = {"reason": None}

    def record_clock(now: float, next_write: float) -> None:
        try:
            clock_file.record(now, simulation.frame_index, next_write, simulation.period)
        except OSError as error:  # (a full disk costs the file, never a frame)
            if clock_file_error["reason"] is None:
                service.log.warning("%s not written (%s): a restart may put the clock back",
                                    clock_file.path, error.strerror)
            clock_file_error["reason"] = error.strerror
        else:
            clock_file_error["reason"] = None

    def camera_info() -> dict:
        return {"header": header(simulation.stamp_ns, simulation.frame_index),
                **simulation.camera_info()}

    def on_command(link: RobotLinks, twist: dict) -> None:
        linear, angular = twist["linear"][0], twist["angular"][2]  # finite: the schema checked
        if abs(linear) > ABSURD_LINEAR or abs(angular) > ABSURD_ANGULAR:
            raise MessageError(f"not a plausible command: linear {linear:g} m/s, angular "
                               f"{angular:g} rad/s")
        pending.append((link, linear, angular))  # a callback never waits for a render
        if isinstance(twist.get("time"), int):  # the follower's tick, awaited in lockstep
            link.gate.commanded(twist["time"])

    def apply_commands() -> None:
        while pending:
            link, linear, angular = pending.popleft()
            try:  # at the time of the last frame; the safety stop counts from there
                simulation.set_command(linear, angular, robot=link.index)
            except ValueError as error:
                service.reject(service.keys(link.key(keys.CMD_VEL)), str(error))

    allowed_folder = scenario_folder(service.config.scenario)

    def on_control(link: RobotLinks, query) -> None:
        request = None
        try:
            request = decode("SimCommand", query.payload.to_bytes() if query.payload else b"")
            if request["op"] == "reset" and request.get("scenario") is not None:
                # Over the network a scenario is a name, never a path to read (see scenario.py).
                request = {**request, "scenario": str(requested_scenario(request["scenario"],
                                                                         allowed_folder))}
            with frame_lock:
                # The queryable outlives the loop by a moment at shutdown (the runner undeclares it).
                reply = ({"ok": False, "error": "the simulator is stopping"} if service.stop.is_set()
                         else simulation.handle_command(request, link.index))
        except (MessageError, ConfigError) as error:
            reply = {"ok": False, "error": str(error)}
        except Exception as error:  # e.g. RecursionError formatting a 1,000-deep argument
            reply = {"ok": False, "error": f"bad request ({type(error).__name__})"}
        if reply["ok"]:
            service.log.info("sim/control: %s", shorten(request, 300))
        else:
            reply["error"] = shorten(reply["error"], 300)
            service.reject(service.keys(link.key(keys.SIM_CONTROL)), reply["error"])
        query.reply(query.key_expr, encode("SimReply", reply))

    def on_token(key_expr, alive: bool) -> None:
        token = keys.alive_token(service.keys.strip(str(key_expr)))  # (robot, peer)
        link = links_by_name.get(token[0]) if token is not None else None
        if link is not None:
            link.gate.set_alive(token[1], alive)

    for link in links:
        service.subscribe(link.key(keys.CMD_VEL), "Twist", functools.partial(on_command, link))
        service.subscribe(link.key(keys.DETECTED_BALLS), "Ball2DArray",
                          lambda balls, gate=link.gate: gate.answered(balls["header"]["seq"]), count=False)
        service.queryable(link.key(keys.CAMERA_INFO), lambda query: query.reply(
            query.key_expr, encode("CameraInfo", camera_info())))
        service.queryable(link.key(keys.SIM_CONTROL), functools.partial(on_control, link))
    service.live_settings = LIVE_SETTINGS
    tokens = service.session.liveliness().declare_subscriber(alive_keys, lambda sample: on_token(
        sample.key_expr, sample.kind == zenoh.SampleKind.PUT), history=True)
    service.stats.extra = lambda: {
        "real_time_factor": meter.factor(), "frames": simulation.frame_index,
        "render_ms": timing["render_ms"], "lockstep_timeouts": lockstep_timeouts(),
        **({"robots": len(links)} if service.config.robots else {}),
        **({} if simulation.command_time is None
           else {"command_stamp": int(round(simulation.command_time * 1e9)),
                 "command_time": simulation.command_time})}

    # The waits of a frame read the live settings again as they go (common.clock.wait_out), so
    # that a real-time factor, a pacing or a lockstep timeout changed live applies to the wait
    # under way: at real_time_factor 0.01 one frame's wait lasts up to 100 s.
    def realtime_wait(delay: Callable[[SimulatorConfig], float]) -> None:
        """Wait out ``delay(live settings)`` while the pacing stays realtime."""
        wait_out(service.stop, lambda: delay(service.config) if service.config.pacing == "realtime" else 0.0)

    def lockstep_timeout() -> float:
        return service.config.lockstep_timeout

    def lockstep_timeouts() -> int:
        return sum(link.gate.timeouts for link in links)

    def frame(config: SimulatorConfig, next_info: float) -> float:
        """Step, render, pace, publish one frame; returns when the next camera_info is due."""
        if config.pacing == "realtime":
            # A camera exposes just before it delivers. Rendering right after the last publish
            # would put the software rasteriser's threads on both cores while the detector works
            # on that frame, and delay its detection.
            realtime_wait(lambda live: pacer.start_delay(simulation.time + simulation.period,
                                                         live.real_time_factor, time.monotonic(), work.lead()))
        started_work = time.perf_counter()
        with frame_lock:
            apply_commands()
            now = simulation.step_frame(time.time())
            head = header(simulation.stamp_ns, simulation.frame_index)
            rgbs = [None] * len(links)
            if config.publish_images or output_files is not None:
                started = time.perf_counter()
                rgbs = [simulation.render(link.index) for link in links]
                render_seconds.append(time.perf_counter() - started)
                timing["render_ms"] = 1000 * sum(render_seconds) / len(render_seconds)  # last 100
            truths = [simulation.ground_truth(link.index) for link in links]
            if output_files is not None:  # (the first robot's)
                output_files.write(simulation, rgbs[0], truths[0])
        # The frame's message is made before the wait for its delivery time, as a camera
        # converts its frame before it delivers it: none of it is on the frame's way.
        images = [image_message(rgb, head, config) if config.publish_images else None for rgb in rgbs]
        work.add(time.perf_counter() - started_work)
        if config.pacing == "realtime":
            slips = pacer.slips
            realtime_wait(lambda live: pacer.delay(now, live.real_time_factor, simulation.period,
                                                   time.monotonic()))
            service.stats.count("dropped", pacer.slips - slips)
        else:
            pacer.reset()
        for link, image, truth in zip(links, images, truths):
            if image is not None:
                link.images.put(image)
            link.truths.put({"header": head, **truth})
        if now + 1e-6 >= next_info:  # (the core sums time steps: 0.99999... is 1 s)
            info = camera_info()
            for link in links:
                link.infos.put(info)
            next_info = math.floor(now + 1e-6) + 1.0
            if clock_file is not None:
                record_clock(now, next_info)
        # Lockstep: time moves on once every robot's detector has answered this frame, and, on
        # the frames whose clock makes a robot's follower's timer fire, once its command is
        # applied; a frame's waits share one deadline (pacing.wait_together).
        lockstep = config.pacing == "lockstep"
        if lockstep and config.publish_images:
            wait_together([functools.partial(link.gate.wait_answer, head["seq"])
                           for link in links if link.gate.alive("detector")], lockstep_timeout)
        if service.stop.is_set():
            return next_info
        for link in links:
            link.clocks.put({"stamp": head["stamp"]})
        period = 1 / config.lockstep_command_rate_hz
        firing = [link for link in links if link.gate.follower_fires(head["stamp"], period)]
        if lockstep:
            wait_together([functools.partial(link.gate.wait_command, head["stamp"]) for link in firing],
                          lockstep_timeout)
        meter.add(time.monotonic(), now)
        return next_info

    def loop(context: ServiceContext) -> None:
        for key in liveliness_keys(context.session, alive_keys, timeout=2.0):  # up before frame 1
            on_token(key, True)
        next_info, next_log = 0.0, time.monotonic() + 5.0
        try:
            while not context.stop.is_set():
                next_info = frame(context.config, next_info)
                if time.monotonic() >= next_log:
                    next_log += 5.0
                    context.log.info("real-time factor %.3f (%.1f frames/s, render %.1f ms, "
                                     "%d lockstep timeouts)", meter.factor(),
                                     meter.frames_per_second(), timing["render_ms"], lockstep_timeouts())
        finally:
            context.log.info("stopped after %d frames (%.2f s simulated), %d lockstep timeouts",
                             simulation.frame_index, simulation.time, lockstep_timeouts())
            tokens.undeclare()
            with frame_lock:
                simulation.close()
            if output_files is not None:
                output_files.close()

    return loop


# The service's parameters (``balltrack run simulator --help`` lists them); ``build`` wires it.
CONFIG = SimulatorConfig


def main(argv=None) -> int:
    return run_service("simulator", CONFIG, build, argv, __doc__)
