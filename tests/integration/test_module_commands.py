"""The modules a user runs with ``python -m`` (experiments, benchmarks, the demo, the README's
parameter tables): each prints its usage for --help, refuses a bad argument with one line and
status 2, ends quietly with status 0 when the reader of its output is gone (``... | head``), as
``balltrack``'s own commands do, and a SIGTERM stops it as Ctrl-C does, with the processes it
started."""

import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from balltrack.deploy.supervisor import pid_alive
from tests.harness import REPO, Process, process_environment, wait_until
from tests.unit.test_real_photos import write_set

MAIN_BLOCK = 'if __name__ == "__main__":'


def module_commands() -> list[str]:
    """Every module of the package with a ``__main__`` block, by its ``balltrack.*`` name (from
    the package map in pyproject.toml, so a new one is found without being listed here)."""
    package_dirs = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    found = set()
    for package, folder in package_dirs.items():
        for path in (REPO / folder).rglob("*.py"):
            if path.name == "__init__.py" or MAIN_BLOCK not in path.read_text():
                continue
            parts = path.relative_to(REPO / folder).with_suffix("").parts
            found.add(".".join((package, *parts)))
    return sorted(found)


def test_the_module_commands_are_found():
    commands = module_commands()
    assert {"balltrack.experiments.real_photos", "balltrack.deploy.demo", "balltrack.deploy.params",
            "balltrack.services.simulator.benchmark"} <= set(commands)
    assert not any(name.endswith("__main__") for name in commands)


@pytest.mark.parametrize("module", module_commands())
def test_a_bad_argument_gets_one_line_and_status_2(module):
    finished = subprocess.run([sys.executable, "-m", module, "--no-such-option"], capture_output=True,
                              text=True, env=process_environment(), cwd=REPO, timeout=120)
    assert finished.returncode == 2, finished.stderr
    lines = finished.stderr.strip().splitlines()
    assert len(lines) == 1, finished.stderr
    assert re.fullmatch(r"(python -m \S+|balltrack \w+): .+", lines[0]), lines[0]
    assert finished.stdout == ""


@pytest.mark.parametrize("module", module_commands())
def test_help_prints_the_usage_and_status_0(module):
    # (argparse formats help texts with %: one stray % in a choice, the variant "specks 2%",
    # once made real_photos --help a traceback)
    finished = subprocess.run([sys.executable, "-m", module, "--help"], capture_output=True, text=True,
                              env=process_environment(), cwd=REPO, timeout=120)
    assert finished.returncode == 0, finished.stderr
    assert finished.stdout.startswith("usage:"), finished.stdout[:200]
    assert finished.stderr == ""


def run_without_reader(arguments: list[str], cwd) -> subprocess.CompletedProcess:
    """``python -m ARGUMENTS`` with its stdout a pipe whose reader is gone before it starts, so
    that its first write fails however little it prints."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        return subprocess.run([sys.executable, "-m", *arguments], stdout=write_end, stderr=subprocess.PIPE,
                              text=True, env=process_environment(), cwd=cwd, timeout=300)
    finally:
        os.close(write_end)


@pytest.mark.parametrize("arguments", [
    ["balltrack.experiments.locator_table"],
    ["balltrack.deploy.params"],
    ["balltrack.experiments.real_photos", "photos", "--no-plain"],
])
def test_a_command_whose_reader_is_gone_ends_quietly(tmp_path, arguments):
    write_set(tmp_path / "photos" / "drawn", [[(200.0, 240.0, 25.0)]])
    finished = run_without_reader(arguments, tmp_path)
    assert finished.returncode == 0, finished.stderr
    assert finished.stderr == ""


@pytest.mark.parametrize("arguments", [["--count", "-1"], ["--no-such-option"],
                                       ["--connect", "localhost:7447"]])  # (no protocol: not an endpoint)
def test_the_example_subscriber_refuses_a_bad_argument_in_one_line(arguments):
    finished = subprocess.run([sys.executable, str(REPO / "examples" / "subscribe_ball3d.py"), *arguments],
                              capture_output=True, text=True, timeout=60)
    assert finished.returncode == 2
    assert len(finished.stderr.strip().splitlines()) == 1, finished.stderr
    assert "Traceback" not in finished.stderr


def descendants(pid: int) -> set[int]:
    """The processes below ``pid`` (Linux: /proc/PID/task/*/children)."""
    found = set()
    for children in Path(f"/proc/{pid}/task").glob("*/children"):
        try:
            for child in map(int, children.read_text().split()):
                found |= {child, *descendants(child)}
        except OSError:  # (a thread or child that ended meanwhile)
            pass
    return found


def command_line(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


@pytest.mark.parametrize("arguments, started", [
    # (a camera service at 30 frames/s; SIGTERM used to leave it running for ever)
    (["-m", "balltrack.experiments.io_throughput", "--seconds", "60"], "run camera"),
    # (a demo: its recorder, and its router, simulator and services under its supervisor; SIGTERM
    # used to leave them running, and killing the demo instead of stopping it, its recorder)
    (["-m", "balltrack", "experiment", "latency", "--quick", "--out", "OUT"], "balltrack record"),
])
def test_sigterm_stops_a_command_with_what_it_started(tmp_path, arguments, started):
    command = Process([sys.executable, *(str(tmp_path) if word == "OUT" else word for word in arguments)],
                      tmp_path / "command.log")

    def started_below() -> set[int] | None:
        found = descendants(command.popen.pid)
        return found if any(started in command_line(pid) for pid in found) else None

    try:
        below = wait_until(started_below, 120, f"a process {started!r} below the command", command)
        assert command.stop(timeout=120) == 1
        assert command.output().splitlines()[-1].endswith(": stopped by a signal"), command.output()[-2000:]
        # (the command waited for what it stopped; a grandchild may take a moment to be reaped)
        wait_until(lambda: not any(pid_alive(pid) for pid in below), 30, "the processes it started to end")
    finally:
        command.kill()
