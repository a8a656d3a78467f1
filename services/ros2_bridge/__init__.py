"""ROS 2 bridge: balltrack's keys as ROS 2 messages in CDR, and a ROS camera as balltrack's.

Converts ``detected_ball`` (geometry_msgs/msg/Point), ``detected_ball_3d`` (PointStamped) and
``cmd_vel`` (Twist) to CDR on ``ros/<topic>``, and a ROS camera's ``sensor_msgs`` Image,
CompressedImage and CameraInfo on ``ros/camera/...`` to ``camera/image_raw`` and
``camera/camera_info``: the keys zenoh-bridge-ros2dds uses with its ``namespace`` set to
``/ros``. The conversions are in :mod:`services.ros2_bridge.convert` (rosbags, no Zenoh).

Example::

    pip install 'balltrack[ros]'
    balltrack run ros2_bridge --connect tcp/127.0.0.1:7447
"""
