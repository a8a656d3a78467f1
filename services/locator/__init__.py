"""Locator: 3D position of the ball from its 2D detection and its known size.

Subscribes to ``detected_ball`` (Ball2D) and ``camera/camera_info`` (CameraInfo) and publishes
``detected_ball_3d`` (Ball3D, camera optical frame) for each detection. Two models, chosen by
``mode``: ``faithful`` is the paper's equations 1-8 (linear in angle, driven by ``h_fov``);
``exact`` is pinhole geometry from CameraInfo intrinsics; ``auto`` (default) is exact once
CameraInfo has been seen. The geometry is in :mod:`services.locator.geometry` (the inverse),
:mod:`services.locator.projection` (a sphere's image) and :mod:`services.locator.camera`.

Example::

    balltrack run locator --connect tcp/127.0.0.1:7447 --set ball_radius=0.033 --set mode=auto
"""
