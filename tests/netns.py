"""Test hosts in Linux network namespaces: several "machines" on one private LAN, on one box.

    available, reason = netns_available()
    with NetworkNamespaces(("a", "b", "c")) as network:
        network.address("a")                  # "10.213.0.1"
        network.command("b", [python, "-m", "balltrack.services.locator", ...])  # argv for Popen
        port = network.free_port("a")
        network.cut("c"); ...; network.heal("c")   # unplug c from the switch, plug it back

The layout is a switch: a fourth namespace ``<base>-net`` holds a Linux bridge, and each host
namespace ``<base>-<host>`` has one veth (``eth0``) plugged into it, an address in one /24 and
``lo`` up. Every interface is created directly inside its namespace, so nothing is added to the
namespace the tests run in: its addresses, routes and interface names stay untouched, and the
same private subnet can be reused by parallel runs (their namespaces never see each other).
Names carry a random tag so parallel or aborted runs do not clash; deleting the namespaces
deletes their veths and bridge. Needs root and iproute2's ``ip``.
"""

import os
import re
import secrets
import shutil
import signal
import subprocess
import sys
import time

from tests.harness import wait_until

IP_TIMEOUT = 20.0  # seconds for one `ip` command; they take milliseconds
_availability: tuple[bool, str] | None = None


class NetnsError(RuntimeError):
    """An `ip` command failed; the message is the command and its stderr."""


def _ip(*arguments: str, check: bool = True) -> subprocess.CompletedProcess:
    command = ["ip", *arguments]
    try:
        result = subprocess.run(command, capture_output=True, text=True, timeout=IP_TIMEOUT,
                                stdin=subprocess.DEVNULL)
    except (OSError, subprocess.TimeoutExpired) as error:
        raise NetnsError(f"`{' '.join(command)}` failed: {error}") from None
    if check and result.returncode != 0:
        raise NetnsError(f"`{' '.join(command)}` failed (exit {result.returncode}): "
                         f"{result.stderr.strip() or result.stdout.strip()}")
    return result


def netns_available() -> tuple[bool, str]:
    """Whether this machine can make namespaced test hosts; the reason when it cannot.

    Probes what NetworkNamespaces needs (a namespace, a bridge in it, a veth pair) in a scratch
    namespace that is deleted again. The answer is cached for the process.
    """
    global _availability
    if _availability is not None:
        return _availability
    if not sys.platform.startswith("linux"):
        _availability = (False, f"network namespaces need Linux, this is {sys.platform}")
    elif os.geteuid() != 0:
        _availability = (False, "network namespaces need root (ip netns add); "
                                f"running as uid {os.geteuid()}")
    elif shutil.which("ip") is None:
        _availability = (False, "no `ip` command: install iproute2 (apt-get install iproute2)")
    else:
        probe = f"bt-{secrets.token_hex(3)}-probe"
        try:
            _ip("netns", "add", probe)
            try:
                _ip("-n", probe, "link", "add", "br0", "type", "bridge")
                _ip("-n", probe, "link", "add", "veth0", "type", "veth", "peer", "name", "veth1")
            finally:
                _ip("netns", "delete", probe, check=False)
            _availability = (True, "")
        except NetnsError as error:
            _availability = (False, f"cannot make network namespaces here: {error}")
    return _availability


class NetworkNamespaces:
    """Hosts in their own network namespaces, bridged on one /24: a context manager.

    ``hosts`` are short names (letters/digits, at most 8 characters); host number i (from 0)
    gets ``<subnet>.<i + 1>``. Leaving the context (also on an error) kills any process still
    inside these namespaces and deletes them.
    """

    def __init__(self, hosts=("a", "b", "c"), subnet: str = "10.213.0", prefix: str = "bt"):
        if not re.fullmatch(r"\d{1,3}\.\d{1,3}\.\d{1,3}", subnet):
            raise ValueError(f"subnet: give the first three octets, e.g. 10.213.0, not {subnet!r}")
        if len(hosts) > 250 or len(set(hosts)) != len(hosts):
            raise ValueError("hosts: at most 250 distinct names")
        for host in hosts:
            if not re.fullmatch(r"[a-z0-9]{1,8}", host) or host == "net":
                raise ValueError(f"host name {host!r}: 1-8 lowercase letters or digits, not 'net'")
        self.hosts = tuple(hosts)
        self.base = f"{prefix}-{secrets.token_hex(3)}"
        self.switch = f"{self.base}-net"
        self.names = {host: f"{self.base}-{host}" for host in self.hosts}
        self.addresses = {host: f"{subnet}.{index + 1}" for index, host in enumerate(self.hosts)}
        self._created: list[str] = []

    def __enter__(self) -> "NetworkNamespaces":
        try:
            self._create()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def _add_namespace(self, name: str) -> None:
        _ip("netns", "add", name)
        self._created.append(name)
        _ip("-n", name, "link", "set", "lo", "up")

    def _create(self) -> None:
        self._add_namespace(self.switch)
        _ip("-n", self.switch, "link", "add", "br0", "type", "bridge")
        _ip("-n", self.switch, "link", "set", "br0", "up")
        for host, name in self.names.items():
            self._add_namespace(name)
            port = f"port-{host}"
            # Both ends are created inside their namespaces: nothing appears in ours.
            _ip("link", "add", "eth0", "netns", name, "type", "veth",
                "peer", "name", port, "netns", self.switch)
            _ip("-n", self.switch, "link", "set", port, "master", "br0")
            _ip("-n", self.switch, "link", "set", port, "up")
            _ip("-n", name, "address", "add", f"{self.addresses[host]}/24", "dev", "eth0")
            _ip("-n", name, "link", "set", "eth0", "up")

    def name(self, host: str) -> str:
        return self.names[host]

    def address(self, host: str) -> str:
        return self.addresses[host]

    def command(self, host: str, arguments: list[str], die_with_parent: bool = True) -> list[str]:
        """The argv that runs ``arguments`` on ``host``.

        ``ip netns exec`` and ``setpriv`` exec the next program, so the pid is the program's
        own and signals reach it. With ``die_with_parent`` (and util-linux's setpriv present),
        the program gets SIGTERM when the process that started it dies, so a test run that is
        killed outright leaves no service running in a namespace nobody will clean.
        """
        guard = (["setpriv", "--pdeathsig", "TERM"]
                 if die_with_parent and shutil.which("setpriv") else [])
        return ["ip", "netns", "exec", self.names[host], *guard, *arguments]

    def run(self, host: str, arguments: list[str], timeout: float = 30.0,
            **options) -> subprocess.CompletedProcess:
        return subprocess.run(self.command(host, arguments), capture_output=True, text=True,
                              timeout=timeout, stdin=subprocess.DEVNULL, **options)

    def free_port(self, host: str) -> int:
        """A TCP port that nothing listens on at ``host``'s address, asked of its kernel."""
        # common.network.free_port, run inside the namespace: each namespace has its own ports,
        # so asking in ours would say nothing about the host's.
        probe = ("from balltrack.common.network import free_port; "
                 f"print(free_port(host={self.addresses[host]!r}))")
        result = self.run(host, [sys.executable, "-c", probe])
        if result.returncode != 0:
            raise NetnsError(f"free port on {host}: {result.stderr.strip()}")
        return int(result.stdout.strip())

    def cut(self, host: str) -> None:
        """Unplug ``host`` from the switch: its port goes down, so nothing reaches it or leaves
        it (no RST, no FIN: as a pulled cable or a dead Wi-Fi link) until :meth:`heal`."""
        _ip("-n", self.switch, "link", "set", f"port-{host}", "down")

    def heal(self, host: str) -> None:
        """Plug ``host`` back in; connections that were cut carry on or reconnect."""
        _ip("-n", self.switch, "link", "set", f"port-{host}", "up")

    def pids(self) -> list[int]:
        """Processes still running inside any of these namespaces."""
        found: list[int] = []
        for name in self._created:
            result = _ip("netns", "pids", name, check=False)
            found += [int(word) for word in result.stdout.split() if word.isdigit()]
        return found

    def close(self) -> None:
        """Kill what still runs inside (only our own children can be there), then delete all."""
        def all_gone() -> bool:
            leftovers = self.pids()
            for pid in leftovers:
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            self._reap(leftovers)
            return not leftovers

        try:
            wait_until(all_gone, 10, "the processes inside the namespaces to go")
        except AssertionError:
            pass  # deleting the namespaces below says what is left
        errors = []
        for name in reversed(self._created):
            result = _ip("netns", "delete", name, check=False)
            if result.returncode != 0:
                errors.append(f"{name}: {result.stderr.strip()}")
        self._created.clear()
        if errors:
            raise NetnsError("could not delete namespaces: " + "; ".join(errors))

    @staticmethod
    def _reap(pids: list[int]) -> None:
        """Collect killed children so they leave the namespace (zombies are still listed)."""
        for pid in pids:
            try:
                os.waitpid(pid, os.WNOHANG)
            except ChildProcessError:
                pass


def remove_stale(prefix: str = "bt-", older_than: float = 900.0) -> list[str]:
    """Delete namespaces that aborted runs left behind: ours by name, empty, and old.

    A namespace counts as stale only when its name has our ``<prefix><6 hex>-<host>`` form, no
    process is inside it, and it was made more than ``older_than`` seconds ago (a running test's
    namespaces hold its processes, and are only empty for moments at its start and end), so a concurrent run's fresh namespaces are never touched.
    """
    pattern = re.compile(re.escape(prefix) + r"[0-9a-f]{6}-[a-z0-9]{1,8}")
    removed = []
    for line in _ip("netns", "list", check=False).stdout.splitlines():
        name = line.split()[0] if line.split() else ""
        if not pattern.fullmatch(name):
            continue
        try:
            age = time.time() - os.stat(f"/run/netns/{name}").st_mtime
        except OSError:
            continue
        if age > older_than and not _ip("netns", "pids", name, check=False).stdout.split():
            if _ip("netns", "delete", name, check=False).returncode == 0:
                removed.append(name)
    return removed
