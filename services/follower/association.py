"""Which detection of a frame is the ball being chased, when several balls are in view.

The follower keeps one target (``keep_target``). Gating each frame only against the previous
frame's choice failed in the multiball experiment when two balls crossed in the image: their
detections merged into one that grew for several frames (a few per cent each, less than any
per-frame gate) and drifted toward the other ball, the remembered position and size followed it,
and when the two split neither looked like the remembered target any more, so after the hold the
largest ball elsewhere was taken while the target was in plain view.

So the target is a small track in image coordinates (normalised x, y and apparent size z):

* **predicted position**: the last position plus an image velocity (smoothed over clean matches,
  so the target's own motion and the robot's turning both carry it), at the frame's time;
* **reference size**: the chosen detection's size; but while the target is *crowded* (another
  detection within ``target_gate`` of it in the last ``target_crowd_secs``, or the target
  covered), it follows at most at ``target_size_rate`` (log per second). A ball's apparent
  size changes smoothly (frame to frame well under 5 % in the simulator, even while the robot
  drives); a merge grows the detection faster, and the reference does not follow it. A lone
  target is left to grow as fast as it does: without another ball near, a larger detection at
  its position is the target coming closer (the last metres of an approach grow it by more
  than half a size per second), not a merge.

A frame's detections, while the target is held (matched or covered within ``target_hold_secs``):

* **clean match**: within ``target_gate`` of the predicted position and of a size between the
  reference divided by ``target_shrink_ratio`` (a ball partly hidden or cut by the image edge
  looks smaller) and, when crowded, the reference times ``target_size_ratio`` (only a merge
  makes a ball look larger; alone, ``target_shrink_ratio`` larger). The nearest to the
  predicted position is the target; it updates position, velocity and reference size.
* **covered**: no clean match, but a larger detection's disc contains the predicted position: the
  target is merged into it or behind a nearer ball. The hold goes on and the position coasts
  (kept inside the covering disc) instead of following the merged centre, which lies between
  the balls; but that detection is not steered by (None), as it is mostly the other ball: the
  controller keeps its last command, and loses the target after ``rcv_timeout_secs`` as for
  any absence. When the balls part, the one at the coasted position and of the reference size
  is the target again.
* otherwise none: the target is not in this frame, and no other ball replaces it before the hold
  ends. After it, or with no target yet, the largest ball is taken (the paper's choice) and
  starts a new track.

Pure: times are the caller's float seconds; nothing here reads a clock.
"""

import math
from dataclasses import dataclass

CLEAN = "clean"
COVERED = "covered"
NEW = "new"


@dataclass
class Track:
    """The target's image state: position at ``time``, velocity (per s) and reference size."""

    x: float
    y: float
    velocity_x: float
    velocity_y: float
    size: float
    time: float       # when x, y were last set
    confirmed: float  # when the target was last matched or covered
    crowded: float | None = None  # when another detection was last near it (or it was covered)


@dataclass(frozen=True)
class AssociationSettings:
    """The follower parameters the association uses (see services/follower/config.py)."""

    gate: float
    hold_secs: float
    size_ratio: float
    shrink_ratio: float
    size_rate: float
    velocity_memory: float
    crowd_secs: float

    @classmethod
    def from_config(cls, config) -> "AssociationSettings":
        return cls(gate=config.target_gate, hold_secs=config.target_hold_secs,
                   size_ratio=config.target_size_ratio, shrink_ratio=config.target_shrink_ratio,
                   size_rate=config.target_size_rate,
                   velocity_memory=config.target_velocity_memory,
                   crowd_secs=config.target_crowd_secs)


def _y(ball: dict) -> float:
    # Ball2D always has y; callers that only know x and size (tests, the paper's message)
    # are treated as all on one row.
    return float(ball.get("y", 0.0))


class TargetAssociation:
    """The target's track and the choice of its detection in each frame (module docstring)."""

    def __init__(self, settings: AssociationSettings):
        self.settings = settings
        self.track: Track | None = None
        self.last_kind: str | None = None  # how the last chosen detection was associated

    def reset(self) -> None:
        self.track = None
        self.last_kind = None

    def holding(self, now: float) -> bool:
        """Whether the target is still held at ``now`` (so no other ball may replace it)."""
        track = self.track
        return (track is not None and math.isfinite(now) and track.time <= now
                and now - track.confirmed <= self.settings.hold_secs)

    def predicted(self, now: float) -> tuple[float, float]:
        """Where the target should be at ``now`` (normalised image x, y)."""
        track = self.track
        elapsed = now - track.time
        return track.x + track.velocity_x * elapsed, track.y + track.velocity_y * elapsed

    def choose(self, balls: list[dict], now: float) -> dict | None:
        """The target's detection among ``balls`` (maps with ``x``, ``z`` and optionally ``y``), or
        None when it is not in this frame on its own (missed, or covered); updates the track."""
        usable = [ball for ball in balls if math.isfinite(ball["x"]) and math.isfinite(_y(ball))
                  and math.isfinite(ball["z"]) and ball["z"] > 0]
        if not self.holding(now):
            self.track = None
            if not usable:
                return None
            largest = max(usable, key=lambda ball: ball["z"])
            self.track = Track(largest["x"], _y(largest), 0.0, 0.0, largest["z"], now, now)
            self.last_kind = NEW
            return largest
        if not usable:
            return None
        settings = self.settings
        track = self.track
        predicted_x, predicted_y = self.predicted(now)

        def distance(ball: dict) -> float:
            return math.hypot(ball["x"] - predicted_x, _y(ball) - predicted_y)

        def size_mismatch(ball: dict) -> float:
            return math.log(ball["z"] / track.size)

        near = [ball for ball in usable if distance(ball) <= settings.gate]
        if len(near) > 1:
            track.crowded = now
        crowded = track.crowded is not None and 0 <= now - track.crowded <= settings.crowd_secs
        larger = settings.size_ratio if crowded else settings.shrink_ratio
        clean = [ball for ball in near
                 if -math.log(settings.shrink_ratio) <= size_mismatch(ball) <= math.log(larger)]
        if clean:
            # Size only gates: after a merge the reference may still be a little off, while
            # the predicted position has kept to the target's own motion.
            chosen = min(clean, key=distance)
            self._follow(chosen, now, crowded)
            self.last_kind = CLEAN
            return chosen
        covering = [ball for ball in usable if ball["z"] > track.size and distance(ball) <= ball["z"]]
        if not covering:
            return None
        track.crowded = now
        self._coast(min(covering, key=distance), predicted_x, predicted_y, now)
        self.last_kind = COVERED
        return None

    def _follow(self, ball: dict, now: float, crowded: bool) -> None:
        track = self.track
        elapsed = now - track.time
        if elapsed > 0:
            memory = self.settings.velocity_memory
            track.velocity_x = memory * track.velocity_x + (1 - memory) * (ball["x"] - track.x) / elapsed
            track.velocity_y = memory * track.velocity_y + (1 - memory) * (_y(ball) - track.y) / elapsed
        track.x, track.y = ball["x"], _y(ball)
        if crowded:
            self._follow_size(ball["z"], elapsed)
        else:
            track.size = ball["z"]
        track.time = track.confirmed = now

    def _coast(self, ball: dict, predicted_x: float, predicted_y: float, now: float) -> None:
        track = self.track
        # The target is somewhere inside the covering disc (radius z in normalised x units).
        track.x = min(max(predicted_x, ball["x"] - ball["z"]), ball["x"] + ball["z"])
        track.y = predicted_y
        self._follow_size(ball["z"], now - track.time)
        track.time = track.confirmed = now

    def _follow_size(self, size: float, elapsed: float) -> None:
        # Rate-limited, so that a merge is not followed.
        step = self.settings.size_rate * max(elapsed, 0.0)
        change = min(max(math.log(size / self.track.size), -step), step)
        self.track.size *= math.exp(change)
