"""The package as a user installs it: one import root, a wheel that runs from anywhere, and
the import layers (import-linter contracts in pyproject.toml) checked on what is shipped."""

import json
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import cv2
import pytest

from tests.harness import REPO, draw_ball, floor_image

PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
# The repository's folders that install under balltrack (see [tool.setuptools] package-dir).
PACKAGE_DIRS = PYPROJECT["tool"]["setuptools"]["package-dir"]


def run(arguments, **options):
    return subprocess.run(arguments, capture_output=True, text=True, timeout=300, **options)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("wheel")
    built = run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q",
                 "--disable-pip-version-check", "-w", str(folder), str(REPO)])
    assert built.returncode == 0, built.stderr
    (path,) = folder.glob("balltrack-*.whl")
    return path


@pytest.fixture(scope="module")
def unpacked(wheel, tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("site")
    with zipfile.ZipFile(wheel) as archive:
        archive.extractall(folder)
    return folder


def test_every_package_folder_is_listed_for_installation():
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    found = set()
    for package, folder in PACKAGE_DIRS.items():
        for init in (REPO / folder).rglob("__init__.py"):
            relative = init.parent.relative_to(REPO / folder).parts
            found.add(".".join((package, *relative)))
    assert found == listed


def test_the_wheel_holds_one_top_level_package_and_no_tests(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    top_level = {name.split("/", 1)[0] for name in names}
    assert top_level == {"balltrack", wheel.name.split("-py3")[0] + ".dist-info"}
    assert not [name for name in names if "/tests/" in name or "/examples/" in name]
    # Data read with importlib.resources travels with the code.
    for data in ("balltrack/services/simulator/scenarios/chase.toml",
                 "balltrack/deploy/config/demo/follower.toml", "balltrack/deploy/zenoh/router.json5"):
        assert data in names


def test_import_layers_hold_in_the_shipped_package(unpacked):
    # Run where the unpacked wheel is the only `balltrack` on the path (not the source tree).
    result = run([str(Path(sys.executable).with_name("lint-imports")), "--config",
                  str(REPO / "pyproject.toml"), "--no-cache"],
                 cwd=unpacked, env={"PYTHONPATH": str(unpacked), "PATH": "/usr/bin:/bin"})
    assert result.returncode == 0, result.stdout + result.stderr
    assert "3 kept, 0 broken" in result.stdout, result.stdout


@pytest.fixture(scope="module")
def fresh_venv(wheel, tmp_path_factory) -> Path:
    """A new virtual environment with the wheel installed (not editable); its third-party
    dependencies come from this environment's site-packages through a .pth line, so the test
    needs no download. Lines of a .pth file only extend the path: the editable install's own
    .pth hook in that folder is not run, so balltrack can come from the wheel alone."""
    folder = tmp_path_factory.mktemp("venv") / "venv"
    created = run([sys.executable, "-m", "venv", str(folder)])
    assert created.returncode == 0, created.stderr
    python = folder / "bin" / "python"
    site = run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"])
    (Path(site.stdout.strip()) / "balltrack-test-dependencies.pth").write_text(
        sysconfig.get_paths()["purelib"] + "\n")
    installed = run([str(python), "-m", "pip", "install", "-q", "--no-deps", "--no-index",
                     "--disable-pip-version-check", str(wheel)])
    assert installed.returncode == 0, installed.stderr
    return folder


@pytest.mark.slow  # (a fresh virtual environment: left to the whole suite, out of the quick tier)
def test_the_installed_wheel_runs_from_any_folder(fresh_venv, tmp_path):
    command = fresh_venv / "bin" / "balltrack"
    where = run([str(fresh_venv / "bin" / "python"), "-c",
                 "import balltrack.common.keys as k, balltrack.services.detector as d; "
                 "print(k.__file__); print(d.__file__)"], cwd=tmp_path)
    assert where.returncode == 0, where.stderr
    assert all(str(fresh_venv) in line for line in where.stdout.splitlines())

    assert run([str(command), "--help"], cwd=tmp_path).returncode == 0
    detector_help = run([str(command), "run", "detector", "--help"], cwd=tmp_path)
    assert detector_help.returncode == 0 and "balltrack run detector" in detector_help.stdout

    # A folder with its own `common` package must not shadow balltrack's.
    (tmp_path / "common").mkdir()
    (tmp_path / "common" / "__init__.py").write_text("raise ImportError('not balltrack')\n")
    image = tmp_path / "ball.png"
    cv2.imwrite(str(image), draw_ball(floor_image(), 320.0, 240.0, 30.0))
    detected = run([str(command), "detect", str(image)], cwd=tmp_path)
    assert detected.returncode == 0, detected.stderr
    (ball,) = json.loads(detected.stdout)["balls"]
    assert abs(ball["u"] - 320) < 1.5 and abs(ball["v"] - 240) < 1.5

    module = run([str(fresh_venv / "bin" / "python"), "-m", "balltrack.services.locator",
                  "--set", "ball_radius=-1"], cwd=tmp_path)
    assert module.returncode == 2 and "ball_radius" in module.stderr
