"""A ``balltrack`` command as a child process of another program (the demo's recorder, the
experiments' viewers and recorders): its output in a log file, waits on what it prints."""

import re
import subprocess
import sys
from pathlib import Path

from balltrack.common.waiting import poll_until


class Command:
    """``python -m balltrack ARGUMENTS`` (or another ``module`` of the package) as a child
    process, its output (stdout and stderr) in ``log``; waits on what it prints."""

    def __init__(self, arguments: list[str], log: Path, module: str = "balltrack"):
        self.log = log
        self._file = open(log, "wb")
        self.popen = subprocess.Popen([sys.executable, "-m", module, *arguments], stdout=self._file,
                                      stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        self.pid = self.popen.pid

    def output(self) -> str:
        return self.log.read_text(errors="replace")

    def wait_for(self, pattern: str, timeout: float = 60.0) -> re.Match:
        """The first match of the regular expression ``pattern`` in the output, once it comes;
        RuntimeError when the command exits or ``timeout`` passes first."""
        def not_found() -> RuntimeError:
            return RuntimeError(f"balltrack {' '.join(self.popen.args[3:])}: no {pattern!r} "
                                f"(exit {self.popen.poll()}): {self.output()[-500:]}")

        def in_output() -> re.Match | None:
            found = re.search(pattern, self.output(), re.M)
            if found is None and self.popen.poll() is not None:
                raise not_found()
            return found

        found = poll_until(in_output, timeout)
        if found is None:
            raise not_found()
        return found

    def stop(self, timeout: float = 30.0) -> int:
        """SIGTERM, then the exit status (SIGKILL after ``timeout``)."""
        if self.popen.poll() is None:
            self.popen.terminate()
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait()
        self._file.close()
        return self.popen.returncode
