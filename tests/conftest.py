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


@pytest.fixture
def launch(router, session, log_dir):
    """``launch(name, "key=value", ..., wait=True)`` starts ``python -m balltrack.services.<name>`` with
    those ``--set`` overrides against the test's router, waits for its liveliness token, and at
    teardown stops every launched service and checks it exited 0. ``name`` may join several
    services in one process (``detector+locator``: ``balltrack run``, settings
    ``service.key=value``); each one's token is waited for."""
    from balltrack.common.keys import process_services
    from tests.harness import Liveliness, start_service

    started = []
    liveliness = Liveliness(session)

    def start(name: str, *overrides: str, wait: bool = True):
        arguments = [item for override in overrides for item in ("--set", override)]
        process = start_service(name, router.endpoint, log_dir, *arguments)
        started.append(process)
        if wait:
            for service in process_services(name):
                liveliness.wait(service, timeout=40)
        return process

    yield start
    for process in started:
        assert process.stop() == 0, process.output()
