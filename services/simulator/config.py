"""Settings of the simulator service: scene, camera, pacing, robot limits, light overrides.

Example ``simulator.toml``::

    scenario = "multi"
    rate_hz = 30.0
    pacing = "fast"
    light_diffuse = 0.05
"""

import enum
import math
from dataclasses import dataclass

from balltrack.common.config import ConfigError, check_fields, param


class Pacing(enum.StrEnum):
    # Member names equal their values: an Enum hashes by name, so only then does a member
    # find the same dict entries as its plain string.
    realtime = "realtime"
    fast = "fast"
    lockstep = "lockstep"


class Encoding(enum.StrEnum):
    rgb8 = "rgb8"
    bgr8 = "bgr8"
    jpeg = "jpeg"


@dataclass
class SimulatorConfig:
    """One simulator's settings; defaults reproduce the paper's scene at 640x480, 30 Hz."""

    scenario: str = param("chase", "a scenario name (`chase`, `orbit`, `multi`...) from "
                                   "services/simulator/scenarios/ or a path to a .toml")
    # 0 keeps the one robot on the service's own keys, as before fleets existed; N >= 1 robots
    # answer on `robot1/...` to `robotN/...` under the service's namespace (fleet.py).
    robots: int = param(0, "robots in the world: 0 = one robot on the service's own keys; N = robots "
                           "`robot1`..`robotN`, each on its own keys (`robotK/cmd_vel`, "
                           "`robotK/camera/image_raw`, `robotK/sim/ground_truth`, `robotK/clock`...)",
                        low=1, high=64, off=0)
    # Two simulators on two hosts, each holding part of one fleet, give their robots distinct
    # names (and keys) this way: robots = 4 and first_robot = 5 are robot5..robot8.
    first_robot: int = param(1, "with robots >= 1, the number of the first robot: robots `robot<first_robot>` "
                                "onwards (their own balls `tennis<first_robot>`...)", low=1, high=10000)
    width: int = param(640, "camera image width (px)", low=16, high=4096)
    height: int = param(480, "camera image height (px)", low=16, high=4096)
    # Gazebo's default.
    hfov: float = param(1.089, "camera horizontal field of view (rad)", low=0.05, high=3.0)
    # One step_frame() advances 1 / rate_hz seconds.
    rate_hz: float = param(30.0, "camera frames per simulated second", low=1, high=1000)
    # Lockstep waits for the detector's answer and, on command ticks, the follower's cmd_vel,
    # so runs are reproducible whatever the machine's load.
    pacing: Pacing = param(Pacing.realtime, "`realtime` (follows the wall clock), `fast` (as fast as it "
                                            "can) or `lockstep` (waits for the pipeline's answers: "
                                            "reproducible); can be changed live")
    # (a frame waits for its time at the factor it was made with: at the slowest, 100 s)
    real_time_factor: float = param(1.0, "simulated seconds per wall second in `realtime` pacing; can be "
                                              "changed live", low=0.01)
    lockstep_timeout: float = param(0.5, "longest wait for the pipeline per frame in `lockstep` (wall s); "
                                                   "can be changed live", above=0, high=60)
    # Frames whose clock crosses a multiple of 1 / lockstep_command_rate_hz simulated seconds
    # wait for the follower's cmd_vel of that tick (its timer rate, 10 Hz).
    lockstep_command_rate_hz: float = param(10.0, "in `lockstep`, the follower's timer rate whose commands "
                                                  "are waited for; can be changed live", low=0.1, high=1000)
    cmd_timeout: float = param(0.5, "safety stop: no cmd_vel for this long (simulated s) -> velocity 0",
                               above=0)
    max_linear: float = param(0.5, "commands are clamped to this forward speed (m/s)", above=0, high=10)
    max_angular: float = param(2.0, "commands are clamped to this turn rate (rad/s)", above=0, high=20)
    max_linear_accel: float = param(1.0, "largest change of forward speed (m/s^2)", above=0)
    max_angular_accel: float = param(4.0, "largest change of turn rate (rad/s^2)", above=0)
    # light_diffuse is the paper's "diffuse RGB"; an ambient of 0 leaves unlit surfaces black.
    light_diffuse: float = param(-1.0, "main light's diffuse level in [0, 1]; negative = the scenario's",
                                 high=1)
    ambient: float = param(-1.0, "ambient light level in [0, 1]; negative = the scenario's", high=1)
    # The software rasteriser pays for shadows.
    shadows: bool = param(False, "render shadows of the main light (about 2x render time)")
    seed: int = param(0, "seed of the image noise; same seed and commands = identical run", low=0)
    image_noise: float = param(0.0, "standard deviation of Gaussian pixel noise (0-255 levels); 0 = none",
                               low=0, high=100)
    # bgr8 is OpenCV's (the detector's) channel order: the frame needs no conversion on its way
    # to the detector, which shortens the path from frame to detection (the simulator converts
    # before the frame's delivery time, off that path).
    encoding: Encoding = param(Encoding.bgr8, "published image encoding: `bgr8`, `rgb8` or `jpeg`; can be "
                                              "changed live")
    jpeg_quality: int = param(90, "JPEG quality (1-100); can be changed live", low=1, high=100)
    # Changing it live is how a test makes the follower search.
    publish_images: bool = param(True, "publish `camera/image_raw`; false stops the frames (a failed "
                                       "camera) while the world, clock and ground truth go on; can be "
                                       "changed live")
    # (services/simulator/clock_file.py: the supervisor removes it before the first start)
    clock_file: str = param("", "if set, keep a bound on the clock and frame number in this file and, when "
                                "started again with it, go on after it instead of from 0; `balltrack "
                                "deploy` sets <run folder>/simulator.clock")
    video_path: str = param("", "if set, record the rendered frames to this .mp4/.avi")
    ground_truth_path: str = param("", "if set, log ground truth to this JSON-lines file")
    timestep: float = param(0.002, "physics step (s), rounded to a whole number per camera frame; at most "
                                   "1 / rate_hz", low=1e-5)

    def __post_init__(self) -> None:
        check_fields(self)
        if self.first_robot != 1 and self.robots == 0:
            raise ConfigError(f"first_robot: numbers the robots of robots >= 1; with robots = 0 the one "
                              f"robot is on the service's own keys, got first_robot = {self.first_robot}")
        if not self.scenario.strip():
            raise ConfigError("scenario: must name a scenario or a .toml file")
        if self.vfov >= math.radians(175):
            raise ConfigError(f"hfov: the vertical field of view at {self.width}x{self.height} "
                              f"would reach 180 degrees, got {self.hfov}")
        if self.timestep > 1.0 / self.rate_hz:
            raise ConfigError(f"timestep: must not exceed the camera period 1/rate_hz "
                              f"({1.0 / self.rate_hz:.4g} s), got {self.timestep}")

    def preflight(self) -> None:
        """The scenario reads, is valid and holds the robots (see ``common.runner.preflight``): a
        misspelt name or a bad scenario file is refused before a router answers, not after the
        wait for one; the simulator reads it again when it starts."""
        from balltrack.services.simulator.fleet import fleet_layout
        from balltrack.services.simulator.scenario import load_scenario

        # (ConfigError naming the file and the problem, or the robots that do not fit in it)
        fleet_layout(load_scenario(self.scenario), self.robots, self.first_robot)

    @property
    def vfov(self) -> float:
        """Vertical field of view (radians) implied by hfov and the aspect ratio."""
        return 2 * math.atan(math.tan(self.hfov / 2) * self.height / self.width)

    @property
    def period(self) -> float:
        """Simulated seconds per camera frame."""
        return 1.0 / self.rate_hz


# What a running simulator can change through simulator/config; the rest takes a restart.
LIVE_SETTINGS = {"pacing", "real_time_factor", "lockstep_timeout", "lockstep_command_rate_hz",
                 "encoding", "jpeg_quality", "publish_images"}
