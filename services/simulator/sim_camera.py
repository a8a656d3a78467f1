"""The robots' cameras in the simulated world (part of the simulator's pure core, see ``sim.py``):
their MuJoCo renderer and OpenGL context, the pictures they take (the camera image, views for
people, the balls' segmentation), their pinhole model and the projection of points into them.

Every robot's camera has the same size, so one renderer (one OpenGL context and scene) serves
them all: a robot's picture is that renderer pointed at its camera. With several robots a
camera's scene leaves out the robots' and balls' geoms whose bounding spheres lie outside its
view (:meth:`SimCamera._cull`): they could not colour a pixel, and the software rasteriser pays
for each geom drawn, so a picture costs about the same however many robots stand elsewhere.

``Simulation`` holds one per world and takes its lock around every call; the OpenGL (EGL)
context is released after each render, so the next may come from any thread.
"""

import math
import os
from typing import Any

os.environ.setdefault("MUJOCO_GL", "egl")  # (as sim.py: before mujoco is imported)

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from balltrack.services.simulator.config import SimulatorConfig  # noqa: E402
from balltrack.services.simulator.world import CAMERA_NAME, VIEW_NAMES, element_name  # noqa: E402

# A ball this close to the camera plane (m) counts as not in front of it.
MIN_VISIBLE_DEPTH = 1e-3
# The geom group a robot's camera does not draw: geoms outside its view are moved there just
# before it renders (the model's geoms are all in group 0).
OUT_OF_VIEW_GROUP = 5


def release_gl_context() -> None:
    """Unbind the calling thread's EGL context, so that the next render may come from any thread.

    An EGL context can be current in one thread only; mujoco.Renderer makes its context
    current on creation and on each render but never releases it.
    """
    if os.environ.get("MUJOCO_GL", "").lower() != "egl":
        return
    from mujoco import egl

    if egl.EGL_DISPLAY is not None:
        egl.EGL.eglMakeCurrent(egl.EGL_DISPLAY, egl.EGL.EGL_NO_SURFACE, egl.EGL.EGL_NO_SURFACE,
                               egl.EGL.EGL_NO_CONTEXT)


def camera_info(config: SimulatorConfig) -> dict[str, Any]:
    """Pinhole intrinsics of the rendered images (OpenCV pixel convention, see ``sim.py``)."""
    width, height = config.width, config.height
    focal = (width / 2) / math.tan(config.hfov / 2)
    return {
        "width": width,
        "height": height,
        "fx": focal,
        "fy": focal,
        "cx": (width - 1) / 2,
        "cy": (height - 1) / 2,
        "hfov": config.hfov,
        "vfov": config.vfov,
    }


def project(config: SimulatorConfig, point_in_camera) -> tuple[float, float] | None:
    """Pixel (u, v) of an optical-frame point, or None when it is not in front."""
    x, y, z = point_in_camera
    if z <= MIN_VISIBLE_DEPTH:
        return None
    info = camera_info(config)
    return info["cx"] + info["fx"] * x / z, info["cy"] + info["fy"] * y / z


class SimCamera:
    """The cameras of the robots named ``robots`` (services/simulator/fleet.py's names; the
    default, the single robot) on one MuJoCo model and its data (see the module doc). Each
    method takes the robot's index in ``robots``."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, config: SimulatorConfig,
                 robots: list[str] = ("",)):
        self._renderer: mujoco.Renderer | None = mujoco.Renderer(model, config.height, config.width)
        release_gl_context()
        self._model = model
        self._data = data
        self._config = config
        self._robots = list(robots)
        self._camera_ids = [model.camera(element_name(robot, CAMERA_NAME)).id for robot in robots]
        # Views for people draw everything; a robot's camera, with several robots, what it can see.
        self._every_geom = mujoco.MjvOption()
        self._every_geom.geomgroup[OUT_OF_VIEW_GROUP] = 1
        self._in_view = mujoco.MjvOption()
        self._in_view.geomgroup[OUT_OF_VIEW_GROUP] = 0
        # What moves (robots, balls) may be left out; the world's own geoms (floor, walls,
        # distractors, on body 0) are always drawn.
        self._movable = np.flatnonzero(model.geom_bodyid != 0) if len(self._robots) > 1 else np.array([], int)
        self._radii = model.geom_rbound[self._movable]
        half_width = math.tan(config.hfov / 2)
        half_height = math.tan(config.vfov / 2)
        # Sphere-in-frustum test: a side plane is passed by more than r/cos(half angle).
        self._half_tangents = np.array([half_width, half_height])
        self._side_margins = np.sqrt(1 + self._half_tangents ** 2)

    def close(self) -> None:
        """Free the renderer (and its OpenGL context). Safe to call twice; points can still
        be projected afterwards."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def render(self, rng: np.random.Generator, robot: int = 0) -> np.ndarray:
        """The camera image now: H x W x 3 uint8, RGB (plus noise from ``rng`` if image_noise > 0)."""
        renderer = self._live_renderer()
        self._cull(robot)
        renderer.update_scene(self._data, self._camera_ids[robot], self._in_view)
        try:
            image = renderer.render()
        finally:
            release_gl_context()
        if self._config.image_noise > 0:
            noise = rng.normal(0.0, self._config.image_noise, image.shape)
            image = np.clip(image + noise, 0, 255).astype(np.uint8)
        return image

    def render_view(self, view: str, robot: int = 0) -> np.ndarray:
        """An RGB picture for people from one of VIEW_NAMES' cameras (the robot's, or the world's
        ``top``)."""
        if view not in VIEW_NAMES:
            raise ValueError(f"view: must be one of {', '.join(VIEW_NAMES)}, got {view!r}")
        renderer = self._live_renderer()
        camera = view if view == "top" else element_name(self._robots[robot], view)
        renderer.update_scene(self._data, self._model.camera(camera).id, self._every_geom)
        try:
            return renderer.render()
        finally:
            release_gl_context()

    def ball_masks(self, ball_ids: list[str], ball_geoms: list[int], robot: int = 0) -> dict[str, np.ndarray]:
        """Per ball id, the H x W boolean mask of its visible pixels (segmentation rendering)."""
        renderer = self._live_renderer()
        renderer.enable_segmentation_rendering()
        self._cull(robot)
        try:
            renderer.update_scene(self._data, self._camera_ids[robot], self._in_view)
            segmentation = renderer.render()
        finally:
            renderer.disable_segmentation_rendering()
            release_gl_context()
        is_geom = segmentation[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)
        return {ball_id: is_geom & (segmentation[..., 0] == geom_id)
                for ball_id, geom_id in zip(ball_ids, ball_geoms)}

    def world_to_camera(self, point, robot: int = 0) -> np.ndarray:
        """A world point in the camera optical frame (x right, y down, z forward)."""
        camera_id = self._camera_ids[robot]
        rotation = self._data.cam_xmat[camera_id].reshape(3, 3)
        local = rotation.T @ (np.asarray(point, dtype=float) - self._data.cam_xpos[camera_id])
        # MuJoCo cameras look along -z with y up; the optical frame looks along +z with y down.
        return np.array([local[0], -local[1], -local[2]])

    def _cull(self, robot: int) -> None:
        """Move the movable geoms that robot ``robot``'s camera cannot see to OUT_OF_VIEW_GROUP,
        and the others back to group 0 (their bounding spheres against its view's frustum)."""
        if not len(self._movable):
            return
        camera_id = self._camera_ids[robot]
        rotation = self._data.cam_xmat[camera_id].reshape(3, 3)
        # MuJoCo's camera frame: x right, y up, looking along -z.
        local = (self._data.geom_xpos[self._movable] - self._data.cam_xpos[camera_id]) @ rotation
        depth = -local[:, 2]
        sideways = np.abs(local[:, :2])
        radii = self._radii
        inside = ((depth > -radii)
                  & np.all(sideways <= depth[:, None] * self._half_tangents
                           + radii[:, None] * self._side_margins, axis=1))
        self._model.geom_group[self._movable] = np.where(inside, 0, OUT_OF_VIEW_GROUP)

    def _live_renderer(self) -> mujoco.Renderer:
        if self._renderer is None:
            raise RuntimeError("the simulation is closed")
        return self._renderer
