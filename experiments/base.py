"""What every experiment shares: options, results with stable names, goals, report, plots.

An experiment module has ``NAME``, ``TITLE`` and ``run(options) -> ExperimentResult``. The
result holds

* ``figures``: every number under a stable name ``<experiment>/<condition>/<metric>`` (slashes,
  so that numbers such as ``diffuse_0.05`` keep their dots), the names tests and people rely on;
* ``goals``: each goal with its target, what was achieved and PASS/MISS (a miss is reported,
  never dropped);
* ``tables``: markdown tables for the report (the paper's figure beside ours where it has one);
* ``plots``: PNG files written into the output folder;
* ``mode``: how it ran: ``in-process`` (simulator, detector and locator cores called directly),
  ``zenoh`` (the real service processes), ``offline`` (image files) or ``skipped``;
* ``date``, ``command`` and ``machine``: when and with which command it ran, and the machine's
  speed then (:func:`machine_speed`), which timings are to be read against.

:func:`write_outputs` merges results into ``DIR/results.json`` (one entry per experiment, a
rerun replaces its entry) and rewrites ``DIR/report.md`` from the merged file.
"""

import json
import math
import os
import platform
import sys
import time
from dataclasses import asdict, dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any, Iterable

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
from tqdm import tqdm  # noqa: E402

RESULTS_FILE = "results.json"
REPORT_FILE = "report.md"
MODES = ("in-process", "zenoh", "offline", "skipped")
# The development photos are not in the repository: without --photos they are looked for in the
# folder this environment variable names, else in shared/data beside the repository (in a
# source checkout, where this file is <repository>/experiments/base.py).
PHOTOS_VARIABLE = "BALLTRACK_PHOTOS"
REPOSITORY = Path(__file__).resolve().parents[1]
SHARED_PHOTOS = REPOSITORY.parent / "shared" / "data"
PHOTOS_DEFAULT_TEXT = f"${PHOTOS_VARIABLE}, else ../shared/data beside the repository"


def development_photos(option: str | Path | None = None) -> Path:
    """The folder of the development photos: ``option`` (a ``--photos`` given), else
    $BALLTRACK_PHOTOS, else SHARED_PHOTOS. It may not exist."""
    if option:
        return Path(option)
    configured = os.environ.get(PHOTOS_VARIABLE)
    return Path(configured) if configured else SHARED_PHOTOS


def shown_path(path: str | Path) -> str:
    """``path`` as a report shows it: relative to the repository when it is beside it (the
    development photos in ../shared/data), so that a report does not name one machine's folders."""
    path = Path(path).resolve()
    if path.is_relative_to(REPOSITORY.parent):
        return os.path.relpath(path, REPOSITORY)
    return str(path)


@dataclass
class Options:
    """Command-line options shared by all experiments."""

    out: Path
    quick: bool = False
    # Overrides the frame (or run) budget per condition of every experiment; None = default.
    frames: int | None = None
    seed: int = 0
    photos: Path | None = None
    # Tracking transport: "auto" (Zenoh services in lockstep if the simulator service works,
    # else in-process), "in-process" or "zenoh".
    transport: str = "auto"
    progress: bool = True
    # --detector / --follower KEY=VALUE: parameters changed from the product's defaults (to try
    # a proposed fix); every experiment uses them and the report lists them.
    detector_overrides: list[str] = field(default_factory=list)
    follower_overrides: list[str] = field(default_factory=list)
    # --view KEY=VALUE: what `balltrack view` sends Rerun's page, changed (live_view).
    view_overrides: list[str] = field(default_factory=list)

    def detector_config(self):
        """The detector parameters every experiment uses: defaults plus ``--detector``."""
        from balltrack.common.config import load_config
        from balltrack.services.detector.config import DetectorConfig

        return load_config(DetectorConfig, None, self.detector_overrides)

    def follower_config(self, **experiment_settings):
        """Follower parameters: defaults, then the experiment's own, then ``--follower``."""
        from balltrack.common.config import load_config, parse_overrides
        from balltrack.services.follower.config import FollowerConfig

        overrides = [f"{key}={value}" for key, value in experiment_settings.items()]
        command_line = parse_overrides(self.follower_overrides)
        overrides += [f"{key}={value}" for key, value in command_line.items()]
        return load_config(FollowerConfig, None, overrides)

    def view_config(self):
        """The viewer settings live_view uses: defaults plus ``--view``."""
        from balltrack.common.config import load_config
        from balltrack.deploy.view_config import RerunViewConfig

        return load_config(RerunViewConfig, None, self.view_overrides)

    def budget(self, quick: int, full: int) -> int:
        """Frames (or runs) per condition: ``--frames`` if given, else the quick or full count."""
        if self.frames is not None:
            return max(1, self.frames)
        return quick if self.quick else full


# The libraries whose versions a timing depends on, by distribution name.
LIBRARIES = ("opencv-python-headless", "numpy", "mujoco", "eclipse-zenoh")


def environment() -> dict[str, str]:
    """Python's and the core libraries' versions, and the CPUs, as a report states them."""
    found = {"python": platform.python_version()}
    for library in LIBRARIES:
        try:
            found[library] = metadata.version(library)
        except metadata.PackageNotFoundError:
            found[library] = "not installed"
    model = next((line.split(":", 1)[1].strip() for line in _read_lines("/proc/cpuinfo")
                  if line.startswith("model name")), platform.machine())
    found["cpus"] = f"{os.cpu_count()} x {model}"
    return found


# Reference timings of the machine (see machine_speed): additions in a Python loop, and a 5x5
# Gaussian blur of a 640x480 BGR frame on one OpenCV thread; each the best of several tries.
SPEED_LOOP_ADDITIONS = 1_000_000
SPEED_TRIES = 3
SPEED_BLURS = 20
# And what a small piece of work (encoding a Ball2D message: Python validation, then msgpack)
# costs back to back and after the process has been idle for a 30 Hz camera's frame period,
# as a service is between frames (p50 of SPEED_IDLE_CALLS calls each). Idle, the code and data
# leave the CPU's caches, and the call after it pays to fetch them again, many times the back
# to back cost. Each step of the demo's latency pays that kind of cost, so the latency follows
# the idle figure more than the two above.
SPEED_IDLE = 1.0 / 30.0
SPEED_IDLE_CALLS = 45


def machine_speed() -> dict[str, float]:
    """How fast this machine runs plain Python and OpenCV now, in ms (the best of several tries):
    ``python_loop_ms`` (SPEED_LOOP_ADDITIONS additions in a ``for`` loop) and ``opencv_blur_ms``
    (one blur, see SPEED_BLURS); and what resuming after idling costs, in us: ``encode_us`` and
    ``encode_after_idle_us`` (see SPEED_IDLE).

    The same code's milliseconds change from machine to machine and, on a shared machine, from
    hour to hour. The balltrack detector is bound by Python, the plain pipeline by OpenCV, so
    their ratio moves with these two figures, measured in the same run.
    """
    import cv2
    import numpy as np

    loop = []
    for _ in range(SPEED_TRIES):
        started = time.perf_counter()
        total = 0
        for value in range(SPEED_LOOP_ADDITIONS):
            total += value
        loop.append((time.perf_counter() - started) * 1000)
    frame = np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        blur = []
        for _ in range(SPEED_BLURS):
            started = time.perf_counter()
            cv2.GaussianBlur(frame, (5, 5), 0)
            blur.append((time.perf_counter() - started) * 1000)
    finally:
        cv2.setNumThreads(threads)
    return {"python_loop_ms": min(loop), "opencv_blur_ms": min(blur), **encode_costs()}


def encode_costs() -> dict[str, float]:
    """``encode_us`` and ``encode_after_idle_us``: p50 of encoding one Ball2D message (us),
    calls back to back and calls each after SPEED_IDLE seconds idle."""
    from balltrack.common.messages import encode, header

    ball = {"header": header(1, 1), "x": 0.1, "y": -0.2, "z": 0.05, "u": 352.0, "v": 192.0,
            "radius_px": 16.0, "image_width": 640, "image_height": 480, "score": 0.9}
    costs = {}
    for name, idle in (("encode_us", 0.0), ("encode_after_idle_us", SPEED_IDLE)):
        times = []
        for _ in range(SPEED_IDLE_CALLS):
            if idle:
                time.sleep(idle)
            started = time.perf_counter()
            encode("Ball2D", ball)
            times.append((time.perf_counter() - started) * 1e6)
        costs[name] = sorted(times)[len(times) // 2]
    return costs


def record_machine_speed(result: "ExperimentResult") -> None:
    """``machine_speed``'s figures as ``result.machine``, as figures ``<experiment>/machine/...``
    and a line in the report."""
    speed = machine_speed()
    result.machine = dict(speed)
    for name, value in speed.items():
        result.figure(f"machine/{name}", value)
    result.notes.append(f"Machine speed in this run: {SPEED_LOOP_ADDITIONS:,} additions in a Python loop "
                        f"{speed['python_loop_ms']:.1f} ms, a 5x5 blur of a 640x480 frame "
                        f"{speed['opencv_blur_ms']:.2f} ms (one thread); encoding a Ball2D message "
                        f"{speed['encode_us']:.0f} us back to back, {speed['encode_after_idle_us']:.0f} us "
                        f"after {SPEED_IDLE * 1000:.0f} ms idle (what resuming costs, as a service does "
                        "on each frame); on another day or machine, compare timings relative to these.")


def now_text() -> str:
    """The local date and time to the minute, as results state when they were made."""
    return time.strftime("%Y-%m-%d %H:%M")


def _read_lines(path: str) -> list[str]:
    try:
        return Path(path).read_text(errors="replace").splitlines()
    except OSError:
        return []


@dataclass
class Goal:
    name: str
    description: str
    target: str
    achieved: str
    passed: bool

    @property
    def status(self) -> str:
        return "PASS" if self.passed else "MISS"


@dataclass
class ExperimentResult:
    name: str
    title: str
    mode: str = "in-process"
    mode_note: str = ""
    figures: dict[str, Any] = field(default_factory=dict)
    goals: list[Goal] = field(default_factory=list)
    tables: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    plots: list[str] = field(default_factory=list)
    seconds: float = 0.0
    quick: bool = False
    settings: dict[str, Any] = field(default_factory=dict)
    # Rows [what, the paper's figure, ours] for the report's "paper vs balltrack" table.
    paper: list[list[str]] = field(default_factory=list)
    # What it ran on: timings in ms are the machine's and the libraries' as much as the code's.
    environment: dict[str, str] = field(default_factory=environment)
    # When it ran (its start), the command that ran it, and machine_speed's figures in that run
    # (record_machine_speed, or ``balltrack experiment`` for an experiment that records none).
    date: str = field(default_factory=now_text)
    command: str = ""
    machine: dict[str, float] = field(default_factory=dict)

    def compare(self, what: str, paper: str, ours: str) -> None:
        self.paper.append([what, paper, ours])

    def figure(self, name: str, value: Any) -> Any:
        """Record one figure as ``<experiment>/<name>``; floats are rounded for readability."""
        if isinstance(value, float):
            value = None if not math.isfinite(value) else round(value, 6)
        self.figures[f"{self.name}/{name}"] = value
        return value

    def goal(self, name: str, description: str, target: str, achieved: str, passed: bool) -> Goal:
        goal = Goal(f"{self.name}/{name}", description, target, achieved, bool(passed))
        self.goals.append(goal)
        return goal

    def table(self, headers: list[str], rows: list[list[Any]], caption: str = "") -> None:
        self.tables.append(markdown_table(headers, rows, caption))

    def save_plot(self, figure, out: Path, filename: str) -> None:
        """Save a matplotlib figure as ``out/filename`` (PNG) and list it in the report."""
        out.mkdir(parents=True, exist_ok=True)
        figure.tight_layout()
        figure.savefig(out / filename, dpi=100)
        plt.close(figure)
        if filename not in self.plots:
            self.plots.append(filename)

    def to_json(self) -> dict[str, Any]:
        data = asdict(self)
        data["goals"] = [{**asdict(goal), "name": goal.name, "status": goal.status}
                         for goal in self.goals]
        return data


def progress(iterable: Iterable | None = None, total: int | None = None, desc: str = "",
             options: Options | None = None, unit: str = "frame"):
    """A tqdm progress bar on stderr (off when ``options.progress`` is False)."""
    disable = options is not None and not options.progress
    return tqdm(iterable, total=total, desc=desc, unit=unit, file=sys.stderr, disable=disable,
                leave=False, dynamic_ncols=True, mininterval=0.5)


def markdown_table(headers: list[str], rows: list[list[Any]], caption: str = "") -> str:
    def cell(value: Any) -> str:
        if value is None:
            return "-"
        if isinstance(value, float):
            return f"{value:.3g}"
        return str(value).replace("|", "\\|")

    lines = []
    if caption:
        lines += [caption, ""]
    lines.append("| " + " | ".join(headers) + " |")
    lines.append("| " + " | ".join("---" for _ in headers) + " |")
    for row in rows:
        lines.append("| " + " | ".join(cell(value) for value in row) + " |")
    return "\n".join(lines)


def percent(value: float | None, digits: int = 1) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{100 * value:.{digits}f} %"


def quantile(values: list[float], q: float) -> float | None:
    """The q-quantile (linear interpolation) of ``values``, or None when there are none."""
    finite = sorted(value for value in values if value is not None and math.isfinite(value))
    if not finite:
        return None
    position = q * (len(finite) - 1)
    low = math.floor(position)
    high = min(low + 1, len(finite) - 1)
    return finite[low] + (finite[high] - finite[low]) * (position - low)


def ratio(numerator: float, denominator: float) -> float | None:
    return numerator / denominator if denominator else None


class Stopwatch:
    def __init__(self):
        self.started = time.perf_counter()

    @property
    def seconds(self) -> float:
        return time.perf_counter() - self.started


# ---------------------------------------------------------------------------------------------
# Output files


def load_results(out: Path) -> dict[str, Any]:
    path = Path(out) / RESULTS_FILE
    if not path.exists():
        return {"experiments": {}}
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError:
        return {"experiments": {}}
    if not isinstance(data, dict) or not isinstance(data.get("experiments"), dict):
        return {"experiments": {}}
    return data


def write_outputs(out: Path, results: list[ExperimentResult], order: list[str]) -> dict[str, Any]:
    """Merge ``results`` into ``out/results.json`` and rewrite ``out/report.md``; returns the
    merged document. ``order`` is the experiments' report order."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    merged = load_results(out)
    for result in results:
        merged["experiments"][result.name] = result.to_json()
    ranked = sorted(merged["experiments"],
                    key=lambda name: order.index(name) if name in order else len(order))
    merged["experiments"] = {name: merged["experiments"][name] for name in ranked}
    figures: dict[str, Any] = {}
    goals: list[dict] = []
    for entry in merged["experiments"].values():
        figures.update(entry.get("figures", {}))
        goals.extend(entry.get("goals", []))
    merged["figures"] = figures
    merged["goals"] = goals
    merged["summary"] = {
        "goals": len(goals),
        "passed": sum(1 for goal in goals if goal["passed"]),
        "missed": [goal["name"] for goal in goals if not goal["passed"]],
    }
    (out / RESULTS_FILE).write_text(json.dumps(merged, indent=1) + "\n")
    (out / REPORT_FILE).write_text(render_report(merged))
    return merged


def render_report(merged: dict[str, Any]) -> str:
    lines = ["# balltrack experiments", ""]
    experiments = merged["experiments"]
    lines += ["| experiment | ran | quick | time (s) | goals |", "| --- | --- | --- | --- | --- |"]
    for name, entry in experiments.items():
        goals = entry.get("goals", [])
        passed = sum(1 for goal in goals if goal["passed"])
        goal_text = f"{passed}/{len(goals)} PASS" if goals else "-"
        lines.append(f"| [{name}](#{name}) | {entry['mode']} | {'yes' if entry.get('quick') else 'no'} "
                     f"| {entry.get('seconds', 0):.0f} | {goal_text} |")
    lines.append("")
    if any(entry.get("quick") for entry in experiments.values()):
        lines += ["Quick runs use small budgets (a few frames per condition, two runs per kind of "
                  "start): a rate from a handful of samples, PASS or MISS, is weak evidence; the "
                  "full run (without --quick) measures the same with more samples.", ""]
    comparisons = [(name, row) for name, entry in experiments.items()
                   for row in entry.get("paper", [])]
    if comparisons:
        lines += ["## The paper's figures beside ours", "",
                  "| experiment | what | paper | balltrack |", "| --- | --- | --- | --- |"]
        for name, (what, paper, ours) in comparisons:
            lines.append(f"| {name} | {what} | {paper} | {ours} |")
        lines.append("")
    all_goals = [goal for entry in experiments.values() for goal in entry.get("goals", [])]
    if all_goals:
        lines += ["## Goals", "", "| goal | target | achieved | status |", "| --- | --- | --- | --- |"]
        for goal in all_goals:
            status = "PASS" if goal["passed"] else "**MISS**"
            lines.append(f"| {goal['name']}: {goal['description']} | {goal['target']} "
                         f"| {goal['achieved']} | {status} |")
        lines.append("")
    for name, entry in experiments.items():
        lines += [f'<a id="{name}"></a>', f"## {name}: {entry['title']}", ""]
        how = {"in-process": "in-process (simulator, detector and locator cores called directly, "
                             "no Zenoh)",
               "zenoh": "over Zenoh (router and service processes)",
               "offline": "offline (detector core on image files)",
               "skipped": "skipped"}.get(entry["mode"], entry["mode"])
        lines.append(f"**Ran:** {how}." + (f" {entry['mode_note']}" if entry.get("mode_note") else ""))
        lines.append("")
        if entry.get("settings"):
            settings = ", ".join(f"{key} = {value}" for key, value in entry["settings"].items())
            lines += [f"**Settings:** {settings}", ""]
        if entry.get("environment"):
            versions = ", ".join(f"{key} {value}" for key, value in entry["environment"].items())
            lines += [f"**Environment:** {versions}", ""]
        if entry.get("date"):
            lines += [f"**Date:** {entry['date']}" + (f" (`{entry['command']}`)" if entry.get("command") else ""), ""]
        for note in entry.get("notes", []):
            lines += [note, ""]
        for table in entry.get("tables", []):
            lines += [table, ""]
        goals = entry.get("goals", [])
        if goals:
            lines += ["| goal | target | achieved | status |", "| --- | --- | --- | --- |"]
            for goal in goals:
                status = "PASS" if goal["passed"] else "**MISS**"
                lines.append(f"| {goal['description']} | {goal['target']} | {goal['achieved']} "
                             f"| {status} |")
            lines.append("")
        for plot in entry.get("plots", []):
            lines += [f"![{plot}]({plot})", ""]
    return "\n".join(lines)
