"""Locator service: ``detected_ball`` -> ``detected_ball_3d`` (paper section 2.3).

Subscribes: ``detected_ball`` (Ball2D), ``camera/camera_info`` (CameraInfo, also queried once
at start; kept per frame size, and a detection is located with its own frame size's).
Publishes: ``detected_ball_3d`` (Ball3D, camera optical frame, header copied from the detection
so end-to-end latency stays measurable).

Example:
    balltrack run locator --connect tcp/192.168.1.10:7447 --set ball_radius=0.033 --set mode=auto
"""


from balltrack.common import keys
from balltrack.common.messages import MessageError
from balltrack.common.context import ServiceContext
from balltrack.common.runner import run_service
from balltrack.services.locator.config import LocatorConfig
from balltrack.common.pinhole import Intrinsics
from balltrack.services.locator.geometry import faithful_v_fov, locate_exact, locate_faithful

# Frame sizes whose CameraInfo is kept; a source cycling through more is re-announced anyway.
MAX_SIZES = 16


def build(service: ServiceContext):
    output = service.publisher(keys.DETECTED_BALL_3D, "Ball3D")
    # By frame size: a camera whose frames change size (photos from several cameras, a
    # resolution switch) announces each size's intrinsics, and detections made from frames of
    # one size may still arrive after the next size's CameraInfo.
    cameras: dict[tuple[int, int], Intrinsics] = {}

    def on_camera_info(info: dict) -> None:
        try:
            intrinsics = Intrinsics.from_camera_info(info)
        except ValueError as error:
            raise MessageError(str(error)) from None
        size = (intrinsics.width, intrinsics.height)
        if len(cameras) >= MAX_SIZES and size not in cameras:
            cameras.pop(next(iter(cameras)))
        cameras.pop(size, None)  # re-inserted last: the oldest size is the one to forget
        cameras[size] = intrinsics

    def on_ball(ball: dict) -> None:
        config = service.config
        width, height = ball["image_width"], ball["image_height"]
        intrinsics = cameras.get((width, height))
        matches = intrinsics is not None
        exact = config.resolved_mode(matches) == "exact"
        if exact and not matches:
            # (asked for the pinhole model: the paper's approximation, quietly, is not it)
            raise MessageError(f"mode exact: no CameraInfo for {width}x{height} frames yet")
        try:
            if exact:
                position = locate_exact(ball["u"], ball["v"], ball["radius_px"], intrinsics,
                                        config.ball_radius, config.circle_model)
            else:
                # The camera's fields of view where it told them, else the configured h_fov.
                h_fov = intrinsics.h_fov if matches else config.h_fov
                v_fov = intrinsics.v_fov if matches else faithful_v_fov(config.h_fov, width, height)
                position = locate_faithful(ball["x"], ball["y"], ball["z"], h_fov, v_fov,
                                           config.ball_radius)
        except (ValueError, ZeroDivisionError) as error:
            raise MessageError(f"cannot locate: {error}") from None
        output.put({"header": {**ball["header"], "frame_id": "camera_optical"},
                    "x": position.x, "y": position.y, "z": position.z,
                    "distance": position.distance})

    service.subscribe(keys.CAMERA_INFO, "CameraInfo", on_camera_info)
    service.subscribe(keys.DETECTED_BALL, "Ball2D", on_ball)

    def ask_camera_info() -> None:
        # The simulator also answers camera_info as a query, so a locator started late need
        # not wait up to a second for the next periodic message.
        for reply in service.session.get(service.keys(keys.CAMERA_INFO), timeout=2.0):
            if reply.ok is not None and not cameras:
                service.process(service.keys(keys.CAMERA_INFO), "CameraInfo",
                                 reply.ok.payload.to_bytes(), on_camera_info, count=False)

    service.start_thread(ask_camera_info, "locator-camera-info")
    return None


# The service's parameters (``balltrack run locator --help`` lists them); ``build`` wires it.
CONFIG = LocatorConfig


def main(argv=None) -> int:
    return run_service("locator", CONFIG, build, argv, __doc__)
