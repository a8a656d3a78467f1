"""Fixtures shared by integration and end-to-end tests: a real router on a free port."""

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from tests.harness import Router, client  # noqa: E402


@pytest.fixture
def log_dir(tmp_path):
    return tmp_path


@pytest.fixture
def router(tmp_path):
    running = Router(tmp_path)
    yield running
    assert running.stop() == 0, running.process.output()


@pytest.fixture
def session(router):
    opened = client(router.endpoint)
    yield opened
    opened.close()
