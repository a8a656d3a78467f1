"""The demo's figures, after the paper's: velocities (its Fig. 6), coordinates and path (Fig. 8).

Pure plotting: lists of samples in, PNG files out (matplotlib's Agg backend, no display).
Times are simulated seconds since the scenario started.
"""

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from balltrack.common.geometry import wrap_angle  # noqa: E402


def plot_trajectory(path, estimates: list[tuple[float, dict]], truths: list[tuple[float, dict]],
                    title: str = "") -> None:
    """Left: the ball in the camera frame over time (locator estimate vs ground truth).
    Right: the robot's path in the world, with the ball.

    ``estimates``: (t, Ball3D); ``truths``: (t, GroundTruth)."""
    figure, (coordinates, world) = plt.subplots(1, 2, figsize=(11, 4.2))
    colours = {"x": "tab:red", "y": "tab:green", "z": "tab:blue"}
    if estimates:
        times = [t for t, _ in estimates]
        for axis_name, colour in colours.items():
            coordinates.plot(times, [ball[axis_name] for _, ball in estimates], ".", color=colour,
                             markersize=3, label=f"{axis_name} (locator)")
    visible = [(t, truth["balls"][0]["in_camera"]) for t, truth in truths if truth["balls"]
               and truth["balls"][0]["visible"]]
    if visible:
        times = [t for t, _ in visible]
        for index, (axis_name, colour) in enumerate(colours.items()):
            coordinates.plot(times, [point[index] for _, point in visible], "-", color=colour,
                             linewidth=1, alpha=0.6, label=f"{axis_name} (ground truth)")
    coordinates.set_xlabel("time (s)")
    coordinates.set_ylabel("ball in camera frame (m)")
    coordinates.set_title("ball coordinates (x right, y down, z forward)")
    coordinates.grid(True, alpha=0.3)
    coordinates.legend(fontsize=7, ncol=2)

    if truths:
        xs = [truth["robot"]["x"] for _, truth in truths]
        ys = [truth["robot"]["y"] for _, truth in truths]
        world.plot(xs, ys, "-", color="tab:blue", label="robot path")
        for label, (_, truth), marker in (("start", truths[0], "o"), ("end", truths[-1], "s")):
            robot = truth["robot"]
            world.plot(robot["x"], robot["y"], marker, color="tab:blue", markersize=6)
            world.annotate("", xy=(robot["x"] + 0.15 * math.cos(robot["yaw"]),
                                   robot["y"] + 0.15 * math.sin(robot["yaw"])),
                           xytext=(robot["x"], robot["y"]),
                           arrowprops={"arrowstyle": "->", "color": "tab:blue"})
            world.annotate(label, (robot["x"], robot["y"]), textcoords="offset points",
                           xytext=(6, -12), fontsize=8)
        for ball in truths[-1][1]["balls"]:
            world.add_patch(plt.Circle(ball["position"][:2], ball["radius"], color="yellowgreen",
                                       ec="olive", label=f"ball {ball['id']}"))
        world.set_aspect("equal", adjustable="datalim")
        world.margins(0.15)
    world.set_xlabel("world x (m)")
    world.set_ylabel("world y (m)")
    world.set_title("robot trajectory (world frame)")
    world.grid(True, alpha=0.3)
    world.legend(fontsize=7, loc="best")
    if title:
        figure.suptitle(title, fontsize=10)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def robot_velocities(truths: list[tuple[float, dict]]) -> list[tuple[float, float, float]]:
    """(t, forward speed, yaw rate) of the robot by differencing its ground-truth pose."""
    result = []
    for (t0, a), (t1, b) in zip(truths, truths[1:]):
        dt = t1 - t0
        if dt <= 0:
            continue
        ra, rb = a["robot"], b["robot"]
        dx, dy = rb["x"] - ra["x"], rb["y"] - ra["y"]
        heading = ra["yaw"]
        forward = (dx * math.cos(heading) + dy * math.sin(heading)) / dt
        turn = wrap_angle(rb["yaw"] - ra["yaw"])
        result.append(((t0 + t1) / 2, forward, turn / dt))
    return result


def plot_velocity(path, commands: list[tuple[float, dict]], truths: list[tuple[float, dict]],
                  title: str = "") -> None:
    """Linear and angular velocity over time: the follower's cmd_vel and the robot's motion."""
    figure, (linear, angular) = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    if commands:
        times = [t for t, _ in commands]
        linear.step(times, [twist["linear"][0] for _, twist in commands], where="post",
                    color="tab:blue", label="cmd_vel linear.x")
        angular.step(times, [twist["angular"][2] for _, twist in commands], where="post",
                     color="tab:orange", label="cmd_vel angular.z")
    motion = robot_velocities(truths)
    if motion:
        times = [t for t, _, _ in motion]
        linear.plot(times, [v for _, v, _ in motion], color="grey", linewidth=0.8, alpha=0.7,
                    label="robot (ground truth)")
        angular.plot(times, [w for _, _, w in motion], color="grey", linewidth=0.8, alpha=0.7,
                     label="robot (ground truth)")
    linear.set_ylabel("linear (m/s)")
    angular.set_ylabel("angular (rad/s)")
    angular.set_xlabel("time (s)")
    for axes in (linear, angular):
        axes.grid(True, alpha=0.3)
        axes.legend(fontsize=8, loc="upper right")
    linear.set_title("velocity commands during tracking")
    if title:
        figure.suptitle(title, fontsize=10)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
