"""``trial run``: the profile's node graph on real sensors, as supervised processes.

Each node of the graph (see :func:`ins_gnss_ros.trial.profile.load_profile`) runs as its console
script ``<venv>/bin/<name> --ros-args --params-file PROFILE``. A node that dies is reported on
stderr and restarted after a back-off that doubles per restart (1, 2, 4 ... s, at most
:data:`MAX_BACKOFF_S`), up to ``max_restarts`` times; then the supervisor stops the graph and
exits 1. A node that exits with status 2 rejected its parameters: restarting cannot help, so the
supervisor stops with status 2 at once. SIGINT, SIGTERM and SIGHUP stop every node
(:func:`~ins_gnss_ros.trial.processes.stop_processes`: SIGTERM, their clean shutdown) and exit 0.
The nodes run in a process group of their own: a Ctrl-C at the terminal, which signals the whole
foreground group, reaches the supervisor alone, so each node is stopped once and in order (a
node signalled while still starting up, or twice while shutting down, would print a traceback).
"""
from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

#: Longest wait before a restart, s.
MAX_BACKOFF_S = 30.0
#: Exit status of a node that rejected its parameters (nodes/base.py run()).
PARAMETER_ERROR_STATUS = 2


@dataclass
class NodeRecord:
    """A supervised node: its command, current process and restart history."""

    name: str
    argv: list
    process: subprocess.Popen | None = None
    restarts: int = 0
    next_start: float = 0.0
    exits: list = field(default_factory=list)


class Supervisor:
    """Start, watch and restart the nodes of a profile.

    Parameters
    ----------
    profile : Profile
    max_restarts : int
        Restarts allowed per node before giving up.
    poll_s : float
        How often the processes are checked, s.
    log : file
        Where events are reported (one line each).
    """

    def __init__(self, profile, max_restarts=5, poll_s=0.2, log=sys.stderr):
        bin_dir = Path(sys.executable).parent
        self.nodes = {name: NodeRecord(name, [str(bin_dir / name), "--ros-args", "--params-file",
                                              str(profile.path)])
                      for name in profile.graph}
        self.max_restarts = max_restarts
        self.poll_s = poll_s
        self.log = log
        self.events: list[str] = []
        self._stop = threading.Event()

    def report(self, text: str) -> None:
        self.events.append(text)
        print(f"supervisor: {text}", file=self.log, flush=True)

    def stop(self, *_signal_args) -> None:
        """Ask :meth:`run` to stop the graph (also the SIGINT/SIGTERM/SIGHUP handler)."""
        self._stop.set()

    def run(self, install_signal_handlers=True) -> int:
        """Supervise until stopped; return the exit status (0, 1 gave up, 2 bad parameters)."""
        if install_signal_handlers:
            # SIGHUP too: the nodes, in their own process group, no longer get the terminal's.
            for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
                signal.signal(signum, self.stop)
        status = 0
        try:
            for record in self.nodes.values():
                self._start(record)
            while not self._stop.wait(self.poll_s):
                status = self._check()
                if status:
                    break
        finally:
            self._shutdown()
        return status

    def _start(self, record: NodeRecord) -> None:
        record.process = subprocess.Popen(record.argv, process_group=0)
        self.report(f"started {record.name} (pid {record.process.pid})")

    def _check(self) -> int:
        now = time.monotonic()
        for record in self.nodes.values():
            process = record.process
            if process is not None and process.poll() is not None:
                record.exits.append(process.returncode)
                record.process = None
                if process.returncode == PARAMETER_ERROR_STATUS:
                    self.report(f"{record.name} rejected its parameters (status 2): stopping")
                    return PARAMETER_ERROR_STATUS
                if record.restarts >= self.max_restarts:
                    self.report(f"{record.name} exited with status {process.returncode} after "
                                f"{record.restarts} restarts: giving up")
                    return 1
                backoff = min(MAX_BACKOFF_S, 2.0 ** record.restarts)
                record.next_start = now + backoff
                self.report(f"{record.name} exited with status {process.returncode}; restart "
                            f"{record.restarts + 1}/{self.max_restarts} in {backoff:g} s")
            if record.process is None and now >= record.next_start:
                record.restarts += 1
                self._start(record)
        return 0

    def _shutdown(self, timeout=10.0) -> None:
        from .processes import stop_processes

        stop_processes([r.process for r in self.nodes.values() if r.process is not None],
                       timeout)
        self.report("stopped")
