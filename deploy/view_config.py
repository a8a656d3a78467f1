"""What ``balltrack view`` sends Rerun's web page (``--set KEY=VALUE``).

A page rendering in software (a browser without a GPU, on the robot's own cores) falls behind
a full-rate stream, and Rerun's server then holds back the sender: every message after waits
behind the backlog, and the page shows the past, further back the longer it runs. These
settings keep what is sent small and rare enough for such a page to stay with the present.
"""

from dataclasses import dataclass

from balltrack.common.config import check_fields, param


@dataclass
class RerunViewConfig:
    update_rate_hz: float = param(2.0, "times a second the page gets what came since the last time, all at "
                                       "once: the newest frame and world, every plot point", above=0, high=30)
    frame_width: int = param(320, "frames wider than this (px) are shrunk to it, aspect kept, before "
                                  "they are sent; 0 = as they come", low=16, high=4096, off=0)
    plot_window_s: float = param(30.0, "seconds of the past the time plots show (what the page redraws "
                                       "each time)", above=0, high=3600)
    path_step_m: float = param(0.02, "the robot's path keeps a point once the robot is this far (m) from "
                                     "the last kept one", low=0, high=1)

    def __post_init__(self):
        check_fields(self)
