"""Waiting on real time, for the tests that drive other processes or a browser (the
virtual clock's tests use :func:`afa.testing.until` instead)."""

import asyncio
import time
from collections.abc import Callable
from typing import Any


async def eventually(condition: Callable[[], Any], timeout: float = 15.0,
                     what: str | Callable[[], str] = "the condition",
                     interval: float = 0.02) -> Any:
    """Wait until ``condition()`` is truthy (bounded; not a timing assertion). ``what``
    names it in the failure (a callable: asked then, to say what was seen last)."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"{what() if callable(what) else what} did not hold "
                                 f"within {timeout} s")
        await asyncio.sleep(interval)
