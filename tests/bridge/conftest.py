"""Fixtures of the bridge's tests: peer processes on loopback, never another host
(explicit 127.0.0.1 endpoints, multicast scouting off)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("zenoh", reason="the bridge needs the extra afa[zenoh]")

ROOT = Path(__file__).resolve().parents[2]


def environment() -> dict[str, str]:
    """This checkout first on the path of every child process (never an installed afa)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"]
                                      if env.get("PYTHONPATH") else "")
    return env


class Peer:
    """A child process that prints ``READY {...}`` when up and ``RESULT {...}`` at its
    end; its output is collected by a thread (the pipe never fills)."""

    def __init__(self, args: list[str], *, ready: str = "READY") -> None:
        self.args = args
        self.process = subprocess.Popen(
            [sys.executable, *args], cwd=ROOT, env=environment(), stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True)
        self.lines: list[str] = []
        self.errors: list[str] = []
        self._ready = threading.Event()
        self._marker = ready
        self._threads = [threading.Thread(target=self._read, daemon=True),
                         threading.Thread(target=self._read_errors, daemon=True)]
        for thread in self._threads:
            thread.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.lines.append(line.rstrip("\n"))
            if line.startswith(self._marker):
                self._ready.set()
        self._ready.set()

    def _read_errors(self) -> None:
        assert self.process.stderr is not None
        for line in self.process.stderr:
            self.errors.append(line.rstrip("\n"))

    def wait_ready(self, timeout: float = 30.0) -> None:
        if not self._ready.wait(timeout) or self.process.poll() is not None and not any(
                line.startswith(self._marker) for line in self.lines):
            raise AssertionError(f"{self.args} did not come up:\n" + "\n".join(self.errors))

    def stop(self, timeout: float = 20.0) -> int:
        if self.process.poll() is None:
            self.process.terminate()
        try:
            code = self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            code = self.process.wait(timeout)
        for thread in self._threads:
            thread.join(timeout)
        for stream in (self.process.stdout, self.process.stderr):
            if stream is not None:
                stream.close()
        return code

    def kill(self) -> None:
        self.process.kill()

    def wait(self, timeout: float = 60.0) -> int:
        try:
            code = self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout)
            raise AssertionError(f"{self.args} did not end within {timeout:g} s; its log:\n"
                                 + "\n".join(self.errors[-40:])) from None
        for thread in self._threads:
            thread.join(timeout)
        for stream in (self.process.stdout, self.process.stderr):
            if stream is not None:
                stream.close()
        return code

    def result(self) -> dict[str, Any]:
        for line in self.lines:
            if line.startswith("RESULT "):
                return json.loads(line[len("RESULT "):])  # type: ignore[no-any-return]
        raise AssertionError(f"{self.args} printed no result:\n" + "\n".join(self.errors))


@pytest.fixture
def peers() -> Iterator[list[Peer]]:
    """Start peers with ``peers.append(Peer([...]))``; all are stopped at the end."""
    started: list[Peer] = []
    yield started
    for peer in started:
        peer.stop()
