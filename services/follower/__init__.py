"""Follower: turns ball detections into velocity commands (paper section 2.4).

Subscribes to ``detected_ball`` (Ball2D: its ``x`` and apparent size ``z``) and publishes
``cmd_vel`` (Twist) from a ``rate_hz`` timer: chase the ball with a proportional turn and a
constant forward speed until it looks big enough, and spin to search once it has not been seen
for ``rcv_timeout_secs``. The ROS2 ball_tracker ``follow_ball`` node, as a pure state machine in
:mod:`services.follower.controller`.

Example::

    balltrack run follower --connect tcp/127.0.0.1:7447 --set forward_chase_speed=0.15
"""
