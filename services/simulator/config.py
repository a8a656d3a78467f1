"""Settings of the simulator service: scene, camera, pacing, robot limits, light overrides.

Example ``simulator.toml``::

    scenario = "multi"
    rate_hz = 30.0
    pacing = "fast"
    light_diffuse = 0.05
"""

import math
from dataclasses import dataclass

from balltrack.common.config import ConfigError

PACING_MODES = ("realtime", "fast", "lockstep")
ENCODINGS = ("rgb8", "bgr8", "jpeg")


def _positive(name: str, value: float) -> None:
    if not math.isfinite(value) or value <= 0:
        raise ConfigError(f"{name}: must be a finite number > 0, got {value!r}")


@dataclass
class SimulatorConfig:
    """One simulator's settings; defaults reproduce the paper's scene at 640x480, 30 Hz."""

    # A scenario name from services/simulator/scenarios/ (e.g. "chase") or a path to a .toml.
    scenario: str = "chase"
    # Camera image size (pixels) and horizontal field of view (radians; Gazebo's default 1.089).
    width: int = 640
    height: int = 480
    hfov: float = 1.089
    # Camera frames per simulated second; one step_frame() advances 1 / rate_hz seconds.
    rate_hz: float = 30.0
    # How the service paces frames against the wall clock: "realtime" (sim time follows wall
    # time times real_time_factor), "fast" (as fast as possible) or "lockstep" (each frame waits
    # for the detector's answer and, on command ticks, the follower's cmd_vel, each at most
    # lockstep_timeout wall seconds, so runs are reproducible whatever the machine's load).
    pacing: str = "realtime"
    real_time_factor: float = 1.0
    lockstep_timeout: float = 0.5
    # In lockstep, frames whose clock crosses a multiple of 1 / lockstep_command_rate_hz
    # simulated seconds wait for the follower's cmd_vel of that tick (its timer rate, 10 Hz).
    lockstep_command_rate_hz: float = 10.0
    # Safety stop: no cmd_vel for this many simulated seconds -> commanded velocity 0.
    cmd_timeout: float = 0.5
    # Robot limits: commands are clamped to max_linear (m/s) / max_angular (rad/s), and the
    # applied velocity changes at most max_linear_accel (m/s^2) / max_angular_accel (rad/s^2).
    max_linear: float = 0.5
    max_angular: float = 2.0
    max_linear_accel: float = 1.0
    max_angular_accel: float = 4.0
    # Light overrides; a negative value keeps the scenario's value. Grey levels in [0, 1]:
    # light_diffuse is the main light's diffuse (the paper's "diffuse RGB"), ambient the scene's
    # ambient level (0 = no ambient light: unlit surfaces are black).
    light_diffuse: float = -1.0
    ambient: float = -1.0
    # Shadows from the main light (costs ~2x render time on the software rasteriser).
    shadows: bool = False
    # Seeds the image noise generator; same seed + same commands -> identical output.
    seed: int = 0
    # Standard deviation of Gaussian pixel noise added to rendered images (intensity levels,
    # 0..255); 0 = noiseless.
    image_noise: float = 0.0
    # Published image encoding ("rgb8", "bgr8" or "jpeg") and the JPEG quality (1..100).
    encoding: str = "rgb8"
    jpeg_quality: int = 90
    # Publish camera/image_raw; false stops the frames (a failed camera) while the world, the
    # clock and the ground truth go on. Changed live, e.g. to test the follower's search.
    publish_images: bool = True
    # Optional recordings: an .mp4/.avi of the rendered frames, a JSON-lines ground-truth log.
    video_path: str = ""
    ground_truth_path: str = ""
    # Physics step (s); rounded so a whole number of steps makes one camera period.
    timestep: float = 0.002

    def __post_init__(self) -> None:
        if not self.scenario.strip():
            raise ConfigError("scenario: must name a scenario or a .toml file")
        for name in ("width", "height"):
            value = getattr(self, name)
            if not 16 <= value <= 4096:
                raise ConfigError(f"{name}: must be between 16 and 4096 pixels, got {value}")
        if not (math.isfinite(self.hfov) and 0.05 <= self.hfov <= 3.0):
            raise ConfigError(f"hfov: must be between 0.05 and 3.0 radians, got {self.hfov}")
        vfov = 2 * math.atan(math.tan(self.hfov / 2) * self.height / self.width)
        if vfov >= math.radians(175):
            raise ConfigError("hfov: the vertical field of view would reach 180 degrees")
        _positive("rate_hz", self.rate_hz)
        if self.rate_hz > 1000:
            raise ConfigError(f"rate_hz: must be <= 1000, got {self.rate_hz}")
        if self.pacing not in PACING_MODES:
            raise ConfigError(f"pacing: must be one of {', '.join(PACING_MODES)}, "
                              f"got {self.pacing!r}")
        for name in ("real_time_factor", "lockstep_timeout", "lockstep_command_rate_hz",
                     "cmd_timeout", "max_linear", "max_angular", "max_linear_accel",
                     "max_angular_accel", "timestep"):
            _positive(name, getattr(self, name))
        if self.lockstep_command_rate_hz > 1000:
            raise ConfigError(f"lockstep_command_rate_hz: must be <= 1000, "
                              f"got {self.lockstep_command_rate_hz}")
        if self.max_linear > 10:
            raise ConfigError(f"max_linear: must be <= 10 m/s, got {self.max_linear}")
        if self.max_angular > 20:
            raise ConfigError(f"max_angular: must be <= 20 rad/s, got {self.max_angular}")
        if self.timestep > 1.0 / self.rate_hz:
            raise ConfigError(f"timestep: must not exceed the camera period 1/rate_hz "
                              f"({1.0 / self.rate_hz:.4g} s), got {self.timestep}")
        if self.timestep < 1e-5:
            raise ConfigError(f"timestep: must be >= 1e-5 s, got {self.timestep}")
        for name in ("light_diffuse", "ambient"):
            value = getattr(self, name)
            if not math.isfinite(value) or value > 1.0:
                raise ConfigError(f"{name}: must be <= 1 (negative = scenario's value), "
                                  f"got {value!r}")
        if self.seed < 0:
            raise ConfigError(f"seed: must be >= 0, got {self.seed}")
        if not (math.isfinite(self.image_noise) and 0 <= self.image_noise <= 100):
            raise ConfigError(f"image_noise: must be between 0 and 100, got {self.image_noise}")
        if self.encoding not in ENCODINGS:
            raise ConfigError(f"encoding: must be one of {', '.join(ENCODINGS)}, "
                              f"got {self.encoding!r}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ConfigError(f"jpeg_quality: must be between 1 and 100, got {self.jpeg_quality}")

    @property
    def vfov(self) -> float:
        """Vertical field of view (radians) implied by hfov and the aspect ratio."""
        return 2 * math.atan(math.tan(self.hfov / 2) * self.height / self.width)

    @property
    def period(self) -> float:
        """Simulated seconds per camera frame."""
        return 1.0 / self.rate_hz

