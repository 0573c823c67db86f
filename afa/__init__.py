"""afa: the Architecture for Autonomy as a single-process asyncio component framework.

The public API is re-exported here; the modules behind it are:

- :mod:`afa.events` — the event channel (Notification Service)
- :mod:`afa.naming` — the name registry (Naming Service)
- :mod:`afa.polling` — latest-value slots, servants, proxies, the invoker seam
- :mod:`afa.ports` — typed ports and the catalog
- :mod:`afa.component` — Component and the SPS / PSR / Client patterns
- :mod:`afa.tasks` — owned tasks (the system's task group)
- :mod:`afa.reactor`, :mod:`afa.codec`, :mod:`afa.transport` — device drivers
- :mod:`afa.clock` — wall, virtual and scaled clocks
- :mod:`afa.system` — System: assembly, start/stop, supervision
- :mod:`afa.config` — Miro XML configuration and parameter models
- :mod:`afa.errors` — the exception tree
"""

from afa.clock import Clock, ScaledClock, VirtualClock, WallClock
from afa.codec import DecoderStatistics, Fault, Scan, StreamDecoder
from afa.component import (
    Client,
    Component,
    Context,
    Health,
    PublishServerReactor,
    RestartPolicy,
    State,
    SubscribePublishServer,
)
from afa.config.parameters import Parameters, param
from afa.errors import (
    AfaError,
    ChannelClosed,
    CommandRefused,
    ComponentError,
    ConfigError,
    EDevIO,
    EOutOfBounds,
    ETimeOut,
    InterfaceError,
    NameAlreadyBound,
    NameNotFound,
    NamingError,
    RealDeviceForbidden,
    StartupError,
    TaskFailed,
    TransportClosed,
)
from afa.events import Event, EventChannel, Overflow, Publisher, Subscription
from afa.naming import NameRegistry
from afa.polling import Invoker, LatestSlot, LocalInvoker, PollLayer, Servant, proxy_for
from afa.ports import Catalog, Input, Output
from afa.reactor import Backoff, Reactor
from afa.system import Observer, System
from afa.transport import ByteStream, SerialSpec, TcpSpec, memory_pipe

__version__ = "0.1.0"

__all__ = [
    "AfaError", "Backoff", "ByteStream", "Catalog", "ChannelClosed", "Client", "Clock",
    "CommandRefused", "Component", "ComponentError", "ConfigError", "Context",
    "DecoderStatistics", "EDevIO",
    "EOutOfBounds", "ETimeOut", "Event", "EventChannel", "Fault", "Health", "Input",
    "InterfaceError", "Invoker", "LatestSlot", "LocalInvoker", "NameAlreadyBound",
    "NameNotFound", "NameRegistry", "NamingError", "Observer", "Output", "Overflow",
    "Parameters", "PollLayer", "Publisher", "PublishServerReactor", "Reactor",
    "RealDeviceForbidden", "RestartPolicy", "Scan", "ScaledClock", "SerialSpec", "Servant",
    "StartupError", "State", "StreamDecoder", "SubscribePublishServer", "Subscription",
    "System", "TaskFailed", "TcpSpec", "TransportClosed", "VirtualClock", "WallClock",
    "memory_pipe", "param", "proxy_for",
]
