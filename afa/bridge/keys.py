"""The Zenoh key expressions afa uses (one robot, many processes)::

    afa/<Robot>/event/<Event>                    an event (put; Event.encode() bytes)
    afa/<Robot>/poll/<Name>/<method>             a poll (query; arguments in the payload)
    afa/<Robot>/info/<process>                   what a process runs (query; JSON)
    afa/<Robot>/alive/process/<process>          liveliness: the process is up
    afa/<Robot>/alive/name/<Name>/<process>/<Interface>
                                                 liveliness: <process> serves <Name>
    afa/<Robot>/time/<process>                   lock-step time messages (decision 0011)

Names become single key chunks, so a name or process that cannot be one (empty, or with
``/ * $ ? #``) is never bridged (:func:`chunk_ok`).
"""

from __future__ import annotations

import re

__all__ = ["ROOT", "chunk_ok", "event", "events", "poll", "poll_all", "info", "infos",
           "alive_process", "alive_name", "alive_all", "time_to", "everything", "parse"]

ROOT = "afa"
_CHUNK = re.compile(r"[^/*$?#\s]+")


def chunk_ok(text: str) -> bool:
    """Whether ``text`` can be one chunk of a key expression."""
    return bool(_CHUNK.fullmatch(text))


def event(robot: str, name: str) -> str:
    return f"{ROOT}/{robot}/event/{name}"


def events(robot: str = "*", name: str = "*") -> str:
    """A selector of events (``*`` chunks match any robot or name)."""
    return f"{ROOT}/{robot}/event/{name}"


def poll(robot: str, name: str, method: str) -> str:
    return f"{ROOT}/{robot}/poll/{name}/{method}"


def poll_all(robot: str, name: str) -> str:
    """What the server of ``name`` declares a queryable on."""
    return f"{ROOT}/{robot}/poll/{name}/*"


def info(robot: str, process: str) -> str:
    return f"{ROOT}/{robot}/info/{process}"


def infos(robot: str = "*") -> str:
    return f"{ROOT}/{robot}/info/*"


def alive_process(robot: str, process: str) -> str:
    return f"{ROOT}/{robot}/alive/process/{process}"


def alive_name(robot: str, name: str, process: str, interface: str) -> str:
    return f"{ROOT}/{robot}/alive/name/{name}/{process}/{interface}"


def alive_all(robot: str = "*") -> str:
    return f"{ROOT}/{robot}/alive/**"


def time_to(robot: str, process: str) -> str:
    return f"{ROOT}/{robot}/time/{process}"


def everything(robot: str) -> str:
    """The one data subscription of a bridge: events and time messages, so that they
    reach the loop in the order they arrived (one Zenoh callback thread)."""
    return f"{ROOT}/{robot}/**"


def parse(key: str) -> tuple[str, str, list[str]]:
    """``(robot, kind, rest)`` of an afa key; ValueError for any other key."""
    parts = str(key).split("/")
    if len(parts) < 4 or parts[0] != ROOT:
        raise ValueError(f"not an afa key: {key}")
    return parts[1], parts[2], parts[3:]
