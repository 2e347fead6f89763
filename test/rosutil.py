"""Test helpers for ROS graphs: spin until a condition holds, run a node as a real process."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

VENV_BIN = Path(sys.executable).parent


def spin_until(executor, condition: Callable[[], bool], timeout: float = 10.0, what: str = "") -> None:
    """Spin ``executor`` until ``condition()`` is true; fail after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out after {timeout} s waiting for {what or condition}")
        executor.spin_once(timeout_sec=0.05)


def node_names(node) -> set[str]:
    return {name for name, _ns in node.get_node_names_and_namespaces()}


class NodeProcess:
    """A console-script node started as a real subprocess with ``--ros-args``.

    Usage::

        with NodeProcess("strapdown", params_file=p) as proc:
            proc.wait_on_graph(probe, executor)
    """

    def __init__(self, script: str, *ros_args: str, params_file: Path | None = None,
                 node_name: str | None = None, extra_args: tuple[str, ...] = ()):
        self.script = script
        self.node_name = node_name or script
        args = [str(VENV_BIN / script), *extra_args, "--ros-args", "-r", f"__node:={self.node_name}"]
        if params_file is not None:
            args += ["--params-file", str(params_file)]
        self.args = args + list(ros_args)
        self.log = tempfile.NamedTemporaryFile(prefix=f"{script}_", suffix=".log", delete=False)
        self.proc: subprocess.Popen | None = None

    def __enter__(self) -> "NodeProcess":
        self.proc = subprocess.Popen(self.args, stdout=self.log, stderr=subprocess.STDOUT,
                                     env=dict(os.environ))
        return self

    def output(self) -> str:
        self.log.flush()
        return Path(self.log.name).read_text(errors="replace")

    def wait_on_graph(self, probe, executor, timeout: float = 20.0) -> None:
        """Wait until the node is visible in the ROS graph (or fail with its output)."""
        def seen() -> bool:
            if self.proc.poll() is not None:
                raise RuntimeError(f"{self.script} exited with {self.proc.returncode}:\n{self.output()}")
            return self.node_name in node_names(probe)
        spin_until(executor, seen, timeout, f"{self.node_name} on the graph")

    def stop(self, sig: int = signal.SIGINT, timeout: float = 10.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode

    def __exit__(self, *exc) -> None:
        self.stop()
        self.log.close()
        os.unlink(self.log.name)


def wait_for_endpoints(probe, executor, publishes=(), subscribes=(), timeout: float = 20.0) -> None:
    """Wait until every topic in ``publishes`` has a publisher and in ``subscribes`` a subscriber."""
    def matched() -> bool:
        return (all(probe.count_publishers(t) > 0 for t in publishes)
                and all(probe.count_subscribers(t) > 0 for t in subscribes))
    spin_until(executor, matched, timeout, f"publishers {publishes} and subscribers {subscribes}")
