"""Randomised MuJoCo scenes with exact ground truth: what the learned detector is trained on.

A ``World`` is one compiled MuJoCo model: a floor and backdrop with generated textures, a set
of textured balls of one target colour (felt noise, wear, seams, logos) and clutter (boxes,
cylinders, capsules, flat patches, balls of other colours), some of it near the target's
colour. Building a world costs a model compile and a renderer, so each world serves many
pictures (``World.picture``); per picture everything else is drawn again: where the balls lie
(alone, touching in groups, in the air, cut by the frame edge, hidden behind clutter), their
sizes, the light's colour, direction and strength (sun, shade, dim), the camera's height, tilt
and field of view. ``augment.py`` then adds what lenses and sensors do.

Ground truth per ball: its centre and radius projected through the camera, the share of its
disc inside the frame, and the share of that visible (from a segmentation render).
"""

import colorsys
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import cv2  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

WIDTH, HEIGHT = 640, 480
BALLS = 10
CLUTTER = 16
TEXTURE = 128
CLUTTER_TEXTURES = 3
# The colour range a world's target is found with: as the default tennis-ball range, 25 wide.
HUE_RANGE = 25
# Points on a ball's outline where its ground truth is measured.
OUTLINE_POINTS = 48
# A ball this much of whose in-frame disc is hidden is neither a ball to find nor a false one.
MIN_VISIBLE = 0.5


@dataclass(frozen=True)
class Ball:
    """One ball's ground truth in a picture (pixels)."""

    u: float
    v: float
    radius: float
    in_frame: float  # share of its disc inside the frame
    visible: float   # share of its in-frame disc not hidden


@dataclass
class Picture:
    image: np.ndarray        # BGR uint8
    balls: list[Ball]
    hue_range: tuple[int, int]   # (h_min, h_max), OpenCV hue; h_min > h_max wraps


def _hsv_to_rgb(hue: float, saturation: float, value: float) -> np.ndarray:
    return np.array(colorsys.hsv_to_rgb(hue % 1.0, saturation, value))


def _smooth_noise(rng: np.random.Generator, size: int, scale: int) -> np.ndarray:
    small = rng.random((max(2, size // scale), max(2, size // scale))).astype(np.float32)
    return cv2.resize(small, (size, size), interpolation=cv2.INTER_CUBIC)


def _foliage(rng: np.random.Generator, rgb: np.ndarray, size: int = 256) -> np.ndarray:
    """Leaves or grass: many small ellipses of shades and hues around ``rgb`` over dark gaps."""
    image = np.ones((size, size, 3), np.float32) * rgb * rng.uniform(0.1, 0.4)
    hue, saturation, value = colorsys.rgb_to_hsv(*np.clip(rgb, 0, 1))
    long_side = rng.uniform(3, 14)
    for _ in range(int(rng.integers(150, 500))):
        colour = _hsv_to_rgb(hue + rng.normal(0, 0.03), np.clip(saturation * rng.uniform(0.6, 1.2), 0, 1),
                             np.clip(value * rng.uniform(0.4, 1.3), 0, 1))
        centre = (int(rng.integers(0, size)), int(rng.integers(0, size)))
        axes = (max(1, int(long_side * rng.uniform(0.5, 1.5))), max(1, int(long_side * rng.uniform(0.1, 0.5))))
        cv2.ellipse(image, centre, axes, float(rng.uniform(0, 180)), 0, 360, tuple(float(c) for c in colour), -1)
    return (np.clip(image, 0, 1) * 255).astype(np.uint8)


def _surface_texture(rng: np.random.Generator, rgb: np.ndarray, size: int = 256) -> np.ndarray:
    """A floor or wall picture: base colour with noise, stripes (wood), tiles, lines (court) or
    leaves."""
    kind = rng.choice(["noise", "wood", "tiles", "court", "speckle", "foliage"])
    if kind == "foliage":
        return _foliage(rng, rgb, size)
    base = np.ones((size, size, 3), np.float32) * rgb
    shade = 1.0 + 0.25 * (_smooth_noise(rng, size, int(rng.integers(4, 64))) - 0.5)
    image = base * shade[..., None]
    if kind == "wood":
        rows = np.sin(np.linspace(0, rng.uniform(10, 60), size) + 3 * _smooth_noise(rng, size, 32))
        image *= (1.0 + 0.15 * rows)[..., None]
    elif kind == "tiles":
        step = int(rng.integers(16, 96))
        grid = (np.arange(size) % step < 2)
        image[grid, :] *= 0.6
        image[:, grid] *= 0.6
    elif kind == "court":
        line = _hsv_to_rgb(rng.random(), rng.uniform(0, 0.3), 1.0)
        for _ in range(int(rng.integers(1, 4))):
            at, width = int(rng.integers(0, size)), int(rng.integers(2, 8))
            if rng.random() < 0.5:
                image[at:at + width] = line
            else:
                image[:, at:at + width] = line
    elif kind == "speckle":
        dots = rng.random((size, size)) < 0.05
        image[dots] *= rng.uniform(0.3, 1.6)
    image += rng.normal(0, 0.03, image.shape)
    return (np.clip(image, 0, 1) * 255).astype(np.uint8)


def _seam_distance(directions: np.ndarray) -> np.ndarray:
    """Angular distance of unit vectors to a tennis ball's seam (two interlocking lobes)."""
    t = np.linspace(0, 2 * math.pi, 512, endpoint=False)
    a, b = 0.75, 0.25
    curve = np.stack([a * np.cos(t) + b * np.cos(3 * t), a * np.sin(t) - b * np.sin(3 * t),
                      2 * math.sqrt(a * b) * np.sin(2 * t)], axis=1)
    curve /= np.linalg.norm(curve, axis=1, keepdims=True)
    best = np.full(len(directions), -1.0, np.float32)
    for start in range(0, len(curve), 64):
        best = np.maximum(best, (directions @ curve[start:start + 64].T).max(axis=1))
    return np.arccos(np.clip(best, -1, 1))


def _cube_directions(size: int) -> list[np.ndarray]:
    """Per face of a cube texture (MuJoCo's order: +x -x +y -y +z -z), the unit direction of
    each texel."""
    grid = (np.arange(size) + 0.5) / size * 2 - 1
    u, v = np.meshgrid(grid, -grid)
    one = np.ones_like(u)
    faces = [(one, v, -u), (-one, v, u), (u, one, -v), (u, -one, v), (u, v, one), (-u, v, -one)]
    out = []
    for x, y, z in faces:
        direction = np.stack([x, y, z], axis=-1).reshape(-1, 3)
        out.append(direction / np.linalg.norm(direction, axis=1, keepdims=True))
    return out


def _ball_texture(rng: np.random.Generator, hue: float, directions: list[np.ndarray]) -> np.ndarray:
    """A ball's cube texture, faces stacked vertically: felt of ``hue`` with noise and wear, a
    seam (light or dark) on most, a logo on some."""
    saturation, value = rng.uniform(0.45, 1.0), rng.uniform(0.6, 1.0)
    felt = _hsv_to_rgb(hue, saturation, value)
    seam_colour = _hsv_to_rgb(0, 0, rng.uniform(0.8, 1.0)) if rng.random() < 0.7 else felt * 0.4
    seam_width = rng.uniform(0.03, 0.08) if rng.random() < 0.75 else 0.0
    logo = rng.random() < 0.35
    logo_centre = rng.normal(size=3)
    logo_centre /= np.linalg.norm(logo_centre)
    logo_colour = _hsv_to_rgb(rng.random(), rng.uniform(0, 1), rng.uniform(0, 0.5))
    wear = rng.uniform(0, 0.25)
    faces = []
    for direction in directions:
        size = int(math.sqrt(len(direction)))
        noise = 1.0 + wear * (_smooth_noise(rng, size, 8) - 0.5) + rng.normal(0, 0.04, (size, size))
        face = np.ones((size * size, 3), np.float32) * felt * noise.reshape(-1, 1)
        if seam_width:
            face[_seam_distance(direction) < seam_width] = seam_colour
        if logo:
            across = np.arccos(np.clip(direction @ logo_centre, -1, 1))
            letters = (across < 0.35) & (np.sin(direction[:, 0] * 60) > 0.2)
            face[letters] = logo_colour
        faces.append(face.reshape(size, size, 3))
    return (np.clip(np.concatenate(faces, axis=0), 0, 1) * 255).astype(np.uint8)


def _near_hue(rng: np.random.Generator, target: float) -> float:
    """A hue (0-1) near the target's: inside its range or just outside it."""
    return (target + rng.uniform(-1.3, 1.3) * HUE_RANGE / 2 / 180.0) % 1.0


def _far_hue(rng: np.random.Generator, target: float) -> float:
    return (target + rng.uniform(0.15, 0.85)) % 1.0


class World:
    """One randomised MuJoCo world (see the module doc); ``picture`` draws a new picture."""

    def __init__(self, rng: np.random.Generator, shadows: bool = False):
        self.rng = rng
        # The target's hue (0-1) and the configured range around it, as a user would set it.
        self.target = rng.random()
        centre = self.target * 180 + rng.uniform(-4, 4)
        self.hue_range = (int(round(centre - HUE_RANGE / 2)) % 180, int(round(centre + HUE_RANGE / 2)) % 180)
        with tempfile.TemporaryDirectory() as folder:
            xml = self._mjcf(Path(folder), shadows)
            self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        self.renderer = mujoco.Renderer(self.model, HEIGHT, WIDTH)
        self.camera = self.model.camera("eye").id
        self.ball_geoms = [self.model.geom(f"ball{index}").id for index in range(BALLS)]
        self.clutter_geoms = [self.model.geom(f"clutter{index}").id for index in range(CLUTTER)]
        self.ball_bodies = [self.model.body(f"ball{index}").mocapid[0] for index in range(BALLS)]
        self.clutter_bodies = [self.model.body(f"clutter{index}").mocapid[0] for index in range(CLUTTER)]
        self.clutter_sizes = self.model.geom_size[self.clutter_geoms].copy()

    def close(self) -> None:
        self.renderer.close()

    def _mjcf(self, folder: Path, shadows: bool) -> str:
        rng = self.rng
        assets, bodies = [], []
        floor_rgb = (_hsv_to_rgb(_near_hue(rng, self.target), rng.uniform(0.2, 0.8), rng.uniform(0.2, 0.8))
                     if rng.random() < 0.25 else _hsv_to_rgb(rng.random(), rng.uniform(0, 0.6), rng.uniform(0.1, 0.9)))
        for name, rgb in (("floor", floor_rgb),
                          ("wall", _hsv_to_rgb(_near_hue(rng, self.target), rng.uniform(0.3, 0.9), rng.uniform(0.2, 1.0))
                           if rng.random() < 0.25 else
                           _hsv_to_rgb(rng.random(), rng.uniform(0, 0.5), rng.uniform(0.2, 1.0)))):
            cv2.imwrite(str(folder / f"{name}.png"), cv2.cvtColor(_surface_texture(rng, rgb), cv2.COLOR_RGB2BGR))
            assets.append(f'<texture name="{name}" type="2d" file="{folder / name}.png"/>')
            repeat = rng.uniform(0.5, 4)
            assets.append(f'<material name="{name}" texture="{name}" texrepeat="{repeat:.3g} {repeat:.3g}" '
                          f'texuniform="true" specular="{rng.uniform(0, 0.4):.3g}" '
                          f'reflectance="{rng.uniform(0, 0.15) if name == "floor" else 0:.3g}"/>')
        # Clutter with a surface: leaves, prints and noise, most of them near the target's colour.
        for index in range(CLUTTER_TEXTURES):
            rgb = _hsv_to_rgb(_near_hue(rng, self.target) if rng.random() < 0.7 else rng.random(),
                              rng.uniform(0.3, 1.0), rng.uniform(0.3, 1.0))
            cv2.imwrite(str(folder / f"clutter{index}.png"),
                        cv2.cvtColor(_surface_texture(rng, rgb, 128), cv2.COLOR_RGB2BGR))
            assets.append(f'<texture name="clutter{index}" type="2d" file="{folder / f"clutter{index}"}.png"/>')
            assets.append(f'<material name="clutter{index}" texture="clutter{index}" '
                          f'texrepeat="{rng.uniform(1, 4):.3g} {rng.uniform(1, 4):.3g}" specular="{rng.uniform(0, 0.5):.3g}"/>')
        directions = _cube_directions(TEXTURE)
        for index in range(4):
            picture = _ball_texture(rng, _near_hue(rng, self.target) if rng.random() < 0.15 else
                                    (self.target + rng.uniform(-0.02, 0.02)) % 1.0, directions)
            path = folder / f"ball{index}.png"
            cv2.imwrite(str(path), cv2.cvtColor(picture, cv2.COLOR_RGB2BGR))
            assets.append(f'<texture name="ball{index}" type="cube" file="{path}" gridsize="6 1" '
                          'gridlayout="RLUDFB"/>')
            assets.append(f'<material name="ball{index}" texture="ball{index}" specular="{rng.uniform(0, 0.5):.3g}" '
                          f'shininess="{rng.uniform(0, 0.6):.3g}"/>')
        for index in range(BALLS):
            bodies.append(f'<body name="ball{index}" mocap="true" pos="0 0 -5"><geom name="ball{index}" '
                          f'type="sphere" size="0.033" material="ball{index % 4}"/></body>')
        for index in range(CLUTTER):
            kind = rng.choice(["box", "cylinder", "capsule", "ellipsoid", "patch", "sphere"])
            near = rng.random() < 0.4 and kind != "sphere"
            rgb = _hsv_to_rgb(_near_hue(rng, self.target) if near else _far_hue(rng, self.target),
                              rng.uniform(0.3, 1) if near else rng.uniform(0, 1), rng.uniform(0.2, 1))
            sizes = rng.uniform(0.02, 0.25, 3)
            if kind == "patch":
                kind, sizes = "box", np.array([sizes[0], sizes[1], 0.002])
            if kind == "sphere":
                sizes = sizes[:1]
            elif kind in ("cylinder", "capsule"):
                sizes = sizes[:2]
            surface = (f'material="clutter{int(rng.integers(CLUTTER_TEXTURES))}"' if rng.random() < 0.4 else
                       f'rgba="{rgb[0]:.3g} {rgb[1]:.3g} {rgb[2]:.3g} 1"')
            bodies.append(f'<body name="clutter{index}" mocap="true" pos="0 0 -5"><geom name="clutter{index}" '
                          f'type="{kind}" size="{" ".join(f"{s:.3g}" for s in sizes)}" {surface}/></body>')
        half = 8
        walls = "".join(
            f'<geom type="box" pos="{x} {y} 1.5" size="{sx} {sy} 1.5" material="wall"/>'
            for x, y, sx, sy in ((half, 0, 0.1, half), (-half, 0, 0.1, half), (0, half, half, 0.1), (0, -half, half, 0.1)))
        shadow = 2048 if shadows else 0
        return f"""<mujoco>
  <visual><global offwidth="{WIDTH}" offheight="{HEIGHT}"/>
    <quality shadowsize="{shadow}" offsamples="0"/>
    <headlight active="0" ambient="0 0 0" diffuse="0 0 0" specular="0 0 0"/>
    <map znear="0.002" zfar="60"/></visual>
  <asset>
    <texture name="sky" type="skybox" builtin="gradient" rgb1="{' '.join(f'{c:.3g}' for c in rng.random(3))}"
             rgb2="{' '.join(f'{c:.3g}' for c in rng.random(3))}" width="64" height="64"/>
    {''.join(assets)}
  </asset>
  <worldbody>
    <light name="sun" directional="true" pos="0 0 10" dir="0 0 -1" castshadow="{'true' if shadows else 'false'}"/>
    <light name="lamp" pos="0 0 2" dir="0 0 -1" castshadow="false" cutoff="60"/>
    <geom name="floor" type="plane" size="{half} {half} 0.1" material="floor"/>
    {walls}
    <camera name="eye" pos="0 0 0.3" xyaxes="0 -1 0 0 0 1" fovy="45"/>
    {''.join(bodies)}
  </worldbody>
</mujoco>"""

    # --------------------------------------------------------------------------- pictures
    def _place_camera(self) -> tuple[np.ndarray, np.ndarray, float]:
        rng, model = self.rng, self.model
        height = float(np.exp(rng.uniform(math.log(0.05), math.log(1.6))))
        tilt = math.radians(rng.uniform(0, 25) if height < 0.3 else rng.uniform(5, 70))
        yaw = rng.uniform(-math.pi, math.pi)
        hfov = math.radians(rng.uniform(45, 95))
        fovy = math.degrees(2 * math.atan(math.tan(hfov / 2) * HEIGHT / WIDTH))
        forward = np.array([math.cos(yaw) * math.cos(tilt), math.sin(yaw) * math.cos(tilt), -math.sin(tilt)])
        right = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
        up = np.cross(right, forward)
        position = np.array([rng.uniform(-3, 3), rng.uniform(-3, 3), height])
        # MuJoCo cameras look along -z with y up: columns x = right, y = up, z = -forward.
        rotation = np.stack([right, up, -forward], axis=1)
        quaternion = np.zeros(4)
        mujoco.mju_mat2Quat(quaternion, rotation.flatten())
        model.cam_pos[self.camera] = position
        model.cam_quat[self.camera] = quaternion
        model.cam_fovy[self.camera] = fovy
        focal = (HEIGHT / 2) / math.tan(math.radians(fovy) / 2)
        return position, np.stack([right, -up, forward]), focal

    def _ground_point(self, position, rotation, focal, u: float, v: float, depth: float) -> np.ndarray:
        ray = rotation.T @ np.array([(u - WIDTH / 2) / focal, (v - HEIGHT / 2) / focal, 1.0])
        return position + ray * depth

    def _place(self, position, rotation, focal) -> None:
        rng, model, data = self.rng, self.model, self.data
        # Each ball aimed at a point of the picture (some beyond its edge) at a random depth,
        # then dropped onto the floor (most) or left in the air; some in touching groups.
        count = int(rng.integers(1, BALLS + 1))
        placed: list[tuple[np.ndarray, float]] = []
        index = 0
        while index < BALLS:
            body, geom = self.ball_bodies[index], self.ball_geoms[index]
            if index >= count:
                data.mocap_pos[body] = (0, 0, -20)
                index += 1
                continue
            radius = float(np.exp(rng.uniform(math.log(0.02), math.log(0.13))))
            if placed and rng.random() < 0.35:
                anchor, anchor_radius = placed[int(rng.integers(len(placed)))]
                angle = rng.uniform(0, 2 * math.pi)
                gap = (anchor_radius + radius) * rng.uniform(1.0, 1.15)
                centre = anchor + np.array([math.cos(angle) * gap, math.sin(angle) * gap, 0.0])
                centre[2] = radius if anchor[2] <= anchor_radius + 1e-6 else anchor[2]
            else:
                u, v = rng.uniform(-0.15, 1.15) * WIDTH, rng.uniform(-0.15, 1.15) * HEIGHT
                depth = float(np.exp(rng.uniform(math.log(0.15), math.log(6.0))))
                centre = self._ground_point(position, rotation, focal, u, v, depth)
                if rng.random() < 0.8 or centre[2] < radius:
                    centre[2] = radius
            model.geom_size[geom, 0] = radius
            model.geom_rbound[geom] = radius
            data.mocap_pos[body] = centre
            data.mocap_quat[body] = _random_quaternion(rng)
            placed.append((centre, radius))
            index += 1
        for body, geom, size in zip(self.clutter_bodies, self.clutter_geoms, self.clutter_sizes):
            if rng.random() < 0.5:
                data.mocap_pos[body] = (0, 0, -20)
                continue
            scale = float(np.exp(rng.uniform(math.log(0.2), math.log(1.5))))
            model.geom_size[geom] = size * scale
            model.geom_rbound[geom] = float(np.linalg.norm(size * scale)) * 1.5
            u, v = rng.uniform(-0.1, 1.1) * WIDTH, rng.uniform(-0.1, 1.1) * HEIGHT
            depth = float(np.exp(rng.uniform(math.log(0.5), math.log(8.0))))
            centre = self._ground_point(position, rotation, focal, u, v, depth)
            centre[2] = max(0.0, centre[2]) if rng.random() < 0.3 else float(size[-1] * scale)
            data.mocap_pos[body] = centre
            data.mocap_quat[body] = _random_quaternion(rng, upright=rng.random() < 0.6)

    def _light(self) -> None:
        rng, model = self.rng, self.model
        sun, lamp = model.light("sun").id, model.light("lamp").id
        elevation = math.radians(rng.uniform(10, 90))
        azimuth = rng.uniform(0, 2 * math.pi)
        model.light_dir[sun] = (-math.cos(elevation) * math.cos(azimuth), -math.cos(elevation) * math.sin(azimuth),
                                -math.sin(elevation))
        tint = _hsv_to_rgb(rng.uniform(0.0, 0.7), rng.uniform(0, 0.35), 1.0)
        strength = float(np.exp(rng.uniform(math.log(0.12), math.log(1.5))))
        model.light_diffuse[sun] = tint * strength
        model.light_specular[sun] = tint * strength * rng.uniform(0, 0.6)
        model.light_ambient[sun] = _hsv_to_rgb(rng.uniform(0.0, 0.7), rng.uniform(0, 0.3), 1.0) * rng.uniform(0.03, 0.5)
        on = rng.random() < 0.3
        model.light_diffuse[lamp] = _hsv_to_rgb(rng.uniform(0, 0.7), rng.uniform(0, 0.4), 1.0) * (
            rng.uniform(0.2, 1.0) if on else 0.0)
        model.light_pos[lamp] = (rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(0.5, 3))

    def segmentation(self) -> np.ndarray:
        """The camera's segmentation render of the scene as it stands: per pixel (object id,
        object type)."""
        self.renderer.enable_segmentation_rendering()
        try:
            self.renderer.update_scene(self.data, self.camera)
            return self.renderer.render()
        finally:
            self.renderer.disable_segmentation_rendering()

    def picture(self) -> Picture:
        """A new picture of this world with its balls' ground truth."""
        position, rotation, focal = self._place_camera()
        self._place(position, rotation, focal)
        self._light()
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_camlight(self.model, self.data)
        self.renderer.update_scene(self.data, self.camera)
        rgb = self.renderer.render()
        segmentation = self.segmentation()
        is_geom = segmentation[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)
        balls = []
        for body, geom in zip(self.ball_bodies, self.ball_geoms):
            centre = self.data.mocap_pos[body]
            if centre[2] < -1:
                continue
            ball = self._project(centre, float(self.model.geom_size[geom, 0]), position, rotation, focal,
                                 is_geom & (segmentation[..., 0] == geom))
            if ball is not None:
                balls.append(ball)
        low, high = self.hue_range
        return Picture(image=cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), balls=balls, hue_range=(low, high))

    @staticmethod
    def _project(centre, radius, position, rotation, focal, visible_mask) -> Ball | None:
        """The ball as a labeller would box it: the box of its outline on the picture (off the
        optical axis a sphere's image is an ellipse stretched away from the centre), its centre
        and half its longer side."""
        local = rotation @ (np.asarray(centre) - position)
        distance = float(np.linalg.norm(local))
        if local[2] <= radius or distance <= radius * 1.01:
            return None
        # The outline is where the cone from the camera tangent to the sphere (half-angle
        # asin(R / d) about the ray to its centre) meets the image plane.
        axis = local / distance
        helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        first = np.cross(axis, helper)
        first /= np.linalg.norm(first)
        second = np.cross(axis, first)
        half_angle = math.asin(radius / distance)
        angles = np.linspace(0, 2 * math.pi, OUTLINE_POINTS, endpoint=False)
        rays = (math.cos(half_angle) * axis[None, :] + math.sin(half_angle) *
                (np.cos(angles)[:, None] * first[None, :] + np.sin(angles)[:, None] * second[None, :]))
        if (rays[:, 2] <= 1e-3).any():
            return None
        outline = np.stack([WIDTH / 2 + focal * rays[:, 0] / rays[:, 2] - 0.5,
                            HEIGHT / 2 + focal * rays[:, 1] / rays[:, 2] - 0.5], axis=1)
        low, high = outline.min(axis=0), outline.max(axis=0)
        u, v = (low + high) / 2
        radius_px = float((high - low).max() / 2)
        if radius_px < 1.0 or high[0] < 0 or high[1] < 0 or low[0] > WIDTH - 1 or low[1] > HEIGHT - 1:
            return None
        disc = np.zeros((HEIGHT, WIDTH), np.uint8)
        cv2.fillPoly(disc, [np.round(outline * 16).astype(np.int32)], 1, lineType=cv2.LINE_8, shift=4)
        in_frame_pixels = int(disc.sum())
        if in_frame_pixels == 0:
            return None
        full = cv2.contourArea(outline.astype(np.float32))
        visible = float(np.count_nonzero(visible_mask & (disc > 0))) / in_frame_pixels
        return Ball(u=float(u), v=float(v), radius=radius_px, in_frame=min(1.0, in_frame_pixels / max(full, 1.0)),
                    visible=visible)


def _random_quaternion(rng: np.random.Generator, upright: bool = False) -> np.ndarray:
    if upright:
        angle = rng.uniform(0, 2 * math.pi)
        return np.array([math.cos(angle / 2), 0, 0, math.sin(angle / 2)])
    quaternion = rng.normal(size=4)
    return quaternion / np.linalg.norm(quaternion)
