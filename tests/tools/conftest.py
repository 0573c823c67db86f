"""Fixtures of the tools' tests: a tool run in this process, and small recordings."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from pathlib import Path

import pytest


class Ran:
    def __init__(self, returncode: int, stdout: str, stderr: str) -> None:
        self.returncode, self.stdout, self.stderr = returncode, stdout, stderr


Tool = Callable[..., Ran]


@pytest.fixture
def tool(capsys: pytest.CaptureFixture[str]) -> Tool:
    """``tool("names", ...)``: ``afa names ...`` in this process (afa.cli.main)."""
    from afa.cli import main

    def run(*args: str, check: bool = True) -> Ran:
        capsys.readouterr()
        try:
            code = main(list(args))
        except SystemExit as exc:  # --help, or a command line argparse refuses
            code = int(exc.code or 0)
        out, err = capsys.readouterr()
        if check:
            assert code == 0, err
        return Ran(code, out, err)

    return run


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A recording (afa.log's Recorder) of a small system, 3.5 s from t=0: a laser
    publishing two points ten times a second (the second 2 + 0.1 k m ahead in scan k),
    and a client that polled ModelServer's getTransformation once, at t=0."""
    pytest.importorskip("afa.log.recorder", reason="the log mode needs afa.log")
    from tests.tools.recorded import record

    path = tmp_path_factory.mktemp("log") / "small.mcap"
    asyncio.run(record(path, seconds=3.5))
    return path


@pytest.fixture(scope="module")
def geometry_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same system without the client (no getTransformation was polled), recorded
    with the viewer channels: their static transforms are the recorded geometry."""
    pytest.importorskip("afa.log.recorder", reason="the log mode needs afa.log")
    from tests.tools.recorded import record

    path = tmp_path_factory.mktemp("log") / "geometry.mcap"
    asyncio.run(record(path, seconds=3.5, display=False, viewer=True))
    return path
