"""The one launcher of the whole system for programs: the demo, the experiments, the tests.

    with start_system(run_dir, settings={"simulator": ["pacing=lockstep"]}) as system:
        session = open_session([system.endpoint])
        ...
    # or: system = start_system(...); ...; code = system.stop()

Starts a router on a free local port (``port``, if nothing listens there) and the chosen
services, each with its parameter file from ``config_dir`` and its ``key=value`` settings,
under a background supervisor (``balltrack deploy``'s, see ``deploy/supervisor.py``): one run
folder with ``launch.json``, every process's log and pid, ``status.json``. Each service
declares its liveliness token before the next one starts (the simulator, last, meets a ready
pipeline), and ``start_system`` returns once all of them are alive. A process that crashes is
restarted by the supervisor; one stopped with :meth:`System.stop_service` stays stopped.
"""

import os
import signal
import sys
from pathlib import Path

from balltrack.common.keys import services_of
from balltrack.common.network import free_port
from balltrack.common.waiting import poll_until
from balltrack.deploy.cli import LaunchError, Launched, launch, make_specs, read_pid, read_status, tail

# Start order: the simulator last, so that the pipeline answers its first frame.
SERVICES = ("detector", "locator", "follower", "simulator")


class System:
    """A running router and services (see :func:`start_system`)."""

    def __init__(self, endpoint: str, run_dir: Path, namespace: str, services: tuple[str, ...],
                 launched: Launched):
        self.endpoint = endpoint
        self.run_dir = run_dir
        self.namespace = namespace
        self.services = services
        self.launched = launched

    def pid(self, name: str) -> int | None:
        """The pid of ``name`` (``router`` or a service) while it runs."""
        return read_pid(self.run_dir / f"{name}.pid")

    def children(self) -> dict:
        """Per process: state, restarts, last exit status (the supervisor's ``status.json``)."""
        return (read_status(self.run_dir) or {}).get("children", {})

    def log(self, name: str, lines: int = 15) -> str:
        """The end of ``name``'s log."""
        return tail(self.run_dir / f"{name}.log", lines)

    def stop_service(self, name: str, timeout: float = 30.0) -> dict:
        """SIGTERM to one process (``router`` or a service), then wait until the supervisor
        has seen it exit; its status. Exit 0, a clean stop, is not restarted."""
        pid = self.pid(name)
        if pid is None:
            raise LaunchError(f"{name} is not running (no {name}.pid in {self.run_dir})")
        os.kill(pid, signal.SIGTERM)

        def replaced() -> tuple[dict] | None:
            # (in the status file the supervisor rewrites; a tuple, as the child may be {})
            child = self.children().get(name, {})
            return (child,) if child.get("pid") != pid else None

        found = poll_until(replaced, timeout)
        if found is None:
            raise LaunchError(f"{name} (pid {pid}) still running {timeout:g} s after SIGTERM")
        return found[0]

    def stop(self, timeout: float = 40.0) -> int:
        """Stop everything (services, then the router); the supervisor's exit status: 0 when
        every process exited 0."""
        return self.launched.stop(timeout)

    def __enter__(self) -> "System":
        return self

    def __exit__(self, *exc_info) -> None:
        self.stop()


def start_system(run_dir: Path | str, services: tuple[str, ...] = SERVICES,
                 settings: dict[str, list[str]] | None = None, config_dir: Path | str | None = None,
                 namespace: str = "", port: int = 0, wait: float = 90.0, output=sys.stdout,
                 log_level: str = "INFO", secure: str | Path | None = None, host: str | None = None) -> System:
    """Start a router and ``services`` (in this order) on this host; return once all are alive.

    ``settings`` maps a service to ``key=value`` parameters (applied after its file in
    ``config_dir``); ``port`` is the router's preferred port on 127.0.0.1 (0: any free one).
    Everything gets SIGTERM if this process dies. ``secure``: a profile folder (``balltrack secure
    init``, its certificates naming 127.0.0.1) and its ``host``'s router, over TLS. Raises LaunchError (with everything stopped
    and the ends of the logs in the message) if a process fails or is not alive in ``wait`` s,
    ValueError for a bad namespace."""
    endpoint = f"{'tls' if secure else 'tcp'}/127.0.0.1:{free_port(port)}"
    unknown = set(settings or {}) - set(services_of(services))
    if unknown:
        raise LaunchError(f"settings for {', '.join(sorted(unknown))}, which is not among the services")
    specs, info = make_specs(list(services), {name: list(values) for name, values in (settings or {}).items()},
                             router=True, listen=[endpoint], namespace=namespace,
                             config_dir=str(config_dir) if config_dir else None, log_level=log_level,
                             secure=str(secure) if secure else None, host=host, run_dir=str(run_dir))
    run_dir = Path(run_dir).resolve()
    launched = launch(run_dir, specs, info, wait=wait, output=output, tie_to_parent=True)
    return System(endpoint, run_dir, namespace, tuple(services), launched)
