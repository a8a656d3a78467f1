"""Camera: frames from a real source (a device, a video file, a folder of photos or a stream
URL, all through OpenCV) published as ``camera/image_raw`` and ``camera/camera_info``, exactly
as the simulator publishes them, so the detector and locator run unchanged on real images.

The intrinsics come from a calibration file in the ROS ``camera_info`` YAML format (written by
``balltrack calibrate``, :mod:`services.camera.calibration`), or, without one, from ``hfov``
for an ideal pinhole. Example::

    balltrack run camera --set source=0 --set calibration=camera.yaml
"""
