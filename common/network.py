"""Local TCP ports for routers started by the demo, the experiments and the tests."""

import socket


def free_port(preferred: int = 0, host: str = "127.0.0.1") -> int:
    """``preferred`` if nothing listens on it at ``host``, else (or for 0) a port the kernel
    says is free there now. Another program may still take it before ours binds it: callers
    start their router at once and fail loudly if it cannot listen."""
    for port in ((preferred, 0) if preferred else (0,)):
        with socket.socket() as probe:
            try:
                probe.bind((host, port))
            except OSError:
                continue
            return probe.getsockname()[1]
    raise OSError(f"no free TCP port on {host}")
