"""The simulator's own output files, when its config names them: the rendered frames as a
video (``video_path``) and the ground truth of each frame as JSON lines (``ground_truth_path``).

These are the simulator's record of a run for offline analysis; ``balltrack record`` writes
the messages on the network instead (an MCAP file).
"""

import json
from pathlib import Path
from typing import Any

import numpy as np

from balltrack.common.config import ConfigError
from balltrack.services.simulator.config import SimulatorConfig
from balltrack.services.simulator.sim import Simulation


class OutputFiles:
    """Writes rendered frames to a video file and ground truth to a JSON-lines file (optional)."""

    def __init__(self, video_path: str, ground_truth_path: str, rate_hz: float,
                 width: int, height: int):
        import cv2  # only needed when recording

        self._cv2 = cv2
        self._video = None
        self._log = None
        if video_path:
            fourcc = "MJPG" if video_path.lower().endswith(".avi") else "mp4v"
            Path(video_path).parent.mkdir(parents=True, exist_ok=True)
            self._video = cv2.VideoWriter(video_path, cv2.VideoWriter_fourcc(*fourcc),
                                          rate_hz, (width, height))
            if not self._video.isOpened():
                raise ConfigError(f"video_path: cannot write a video to {video_path}")
        if ground_truth_path:
            Path(ground_truth_path).parent.mkdir(parents=True, exist_ok=True)
            self._log = open(ground_truth_path, "w", encoding="utf-8")

    @classmethod
    def from_config(cls, config: SimulatorConfig) -> "OutputFiles | None":
        """The files of config's video_path / ground_truth_path, or None if both are empty."""
        if not config.video_path and not config.ground_truth_path:
            return None
        return cls(config.video_path, config.ground_truth_path, config.rate_hz,
                   config.width, config.height)

    def write(self, simulation: Simulation, image_rgb: np.ndarray | None = None,
              ground_truth: dict[str, Any] | None = None) -> None:
        """Record the current frame (``image_rgb``) and ground truth of ``simulation``."""
        if self._video is not None and image_rgb is not None:
            self._video.write(self._cv2.cvtColor(image_rgb, self._cv2.COLOR_RGB2BGR))
        if self._log is not None:
            truth = ground_truth if ground_truth is not None else simulation.ground_truth()
            linear, angular = simulation.robot_velocity()
            record = {"stamp": simulation.stamp_ns, "seq": simulation.frame_index,
                      "time": simulation.time, "wall_time": simulation.wall_time,
                      "linear": linear, "angular": angular, **truth}
            self._log.write(json.dumps(record) + "\n")

    def close(self) -> None:
        if self._video is not None:
            self._video.release()
            self._video = None
        if self._log is not None:
            self._log.close()
            self._log = None
