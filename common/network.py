"""Local TCP ports for routers started by the demo, the experiments and the tests."""

import errno
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


def port_taken(port: int, host: str = "0.0.0.0") -> bool:
    """Whether a socket already listens on TCP ``port`` at ``host`` (a router's ``--listen``
    address: 0.0.0.0, an interface's IPv4 or IPv6 address). As a router binds, with
    SO_REUSEADDR: connections of a router just stopped, in TIME_WAIT, do not count."""
    host = host.strip("[]") or "0.0.0.0"
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError as error:
            return error.errno == errno.EADDRINUSE
    return False
