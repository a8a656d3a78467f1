"""What a running process costs, read from Linux's /proc (CPU time, resident memory); the
``balltrack`` commands experiments start are ``deploy/command.py``'s :class:`Command`."""

import os
from pathlib import Path


def cpu_seconds(pid: int | None) -> float:
    """User + system CPU time of a process so far, 0 if it is gone or unknown."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return 0.0


def resident_mb(pid: int | None) -> float | None:
    """VmRSS of ``pid`` in MB (None when it is gone or unknown)."""
    if pid is None:
        return None
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def tree_cpu_seconds(pid: int | None) -> float:
    """:func:`cpu_seconds` of ``pid`` and of all its descendants now alive (a browser's
    renderer and GPU processes: time of children already gone is not counted)."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
        except (OSError, IndexError, ValueError):
            continue
    total, pending = 0.0, [pid] if pid is not None else []
    while pending:
        current = pending.pop()
        total += cpu_seconds(current)
        pending.extend(children.get(current, []))
    return total
