"""Which clock a ``cmd_vel`` carries: the frames', whatever clock the follower's timer runs on.

A deployment has one clock for its data: the stamps of the camera frames (simulated time when
the simulator is the camera). Every command carries it, in its header and in its ``time``:

* **chasing** (or arrived): the header of the detection message the controller last took in,
  unchanged, so latency from frame capture to command can be measured;
* **searching**: no detection is being followed, so the command derives from no frame; it
  carries the frame clock at the tick, with the seq of the last detection message received;
* ``time`` (timer commands only): the frame clock at the tick.

The frame clock at a tick is, with ``use_sim_time``, the ``clock`` stamp that fired the tick
(the simulator publishes each frame's stamp on ``clock``; a lockstep simulator waits for a
command whose ``time`` equals it); on the wall clock, the stamp of the last detection message
received (an empty ``detected_balls`` is a frame seen too). Before any frame (no detection
message and, with ``use_sim_time``, no ``clock`` yet) it is 0 with seq 0, ROS's "no time yet":
a search spin at start-up is not put on the wall clock while the frames that follow are on
another.

The timer and the detection timeout keep running on the follower's own clock (wall or
simulated); only what is stamped is decided here.
"""

from dataclasses import dataclass


@dataclass(frozen=True)
class Stamp:
    """What one command carries: its header's ``stamp`` and ``seq``, and its ``time``."""

    stamp: int
    seq: int
    time: int


class CommandStamps:
    """The frames a follower has seen and the detection it follows; see the module docstring."""

    def __init__(self):
        self._frame_stamp = 0
        self._frame_seq = 0
        self._followed: dict | None = None

    def saw_frame(self, header: dict) -> None:
        """A detection message arrived (``detected_ball``, or ``detected_balls`` even empty)."""
        self._frame_stamp, self._frame_seq = header["stamp"], header["seq"]

    def follow(self, header: dict) -> None:
        """The controller took in the detection of the message with this header."""
        self._followed = header

    def for_tick(self, searching: bool, sim_clock_ns: int | None) -> Stamp:
        """The stamps of a timer command. ``sim_clock_ns``: the ``clock`` stamp that fired the
        tick with ``use_sim_time``, None on the wall clock."""
        frame_now = self._frame_stamp if sim_clock_ns is None else sim_clock_ns
        if searching or self._followed is None:
            return Stamp(frame_now, self._frame_seq, frame_now)
        return Stamp(self._followed["stamp"], self._followed["seq"], frame_now)
