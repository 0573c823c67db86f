"""afa: the Architecture for Autonomy as a single-process asyncio component framework.

The public API is re-exported here; the modules behind it are:

- :mod:`afa.events` — the event channel (Notification Service)
- :mod:`afa.naming` — the name registry (Naming Service)
- :mod:`afa.polling` — latest-value slots, servants and typed client proxies
- :mod:`afa.component` — Component and the SPS / PSR / Client patterns
- :mod:`afa.reactor`, :mod:`afa.codec`, :mod:`afa.transport` — device drivers
- :mod:`afa.clock` — wall and virtual clocks
- :mod:`afa.system` — System: assembly, start/stop, supervision
- :mod:`afa.config` — Miro XML configuration and parameter models
- :mod:`afa.errors` — the exception tree
"""

from afa.clock import Clock, VirtualClock, WallClock
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
    ComponentError,
    ConfigError,
    EDevIO,
    EOutOfBounds,
    ETimeOut,
    InterfaceError,
    NameAlreadyBound,
    NameNotFound,
    NamingError,
    StartupError,
    TransportClosed,
)
from afa.events import Event, EventChannel, Overflow, Publisher, Subscription
from afa.naming import NameRegistry
from afa.polling import LatestSlot, Servant, proxy_for
from afa.reactor import Backoff, Reactor
from afa.system import System
from afa.transport import ByteStream, SerialSpec, TcpSpec, memory_pipe

__version__ = "0.1.0"

__all__ = [
    "AfaError", "Backoff", "ByteStream", "ChannelClosed", "Client", "Clock", "Component",
    "ComponentError", "ConfigError", "Context", "DecoderStatistics", "EDevIO", "EOutOfBounds",
    "ETimeOut", "Event", "EventChannel", "Fault", "Health", "InterfaceError", "LatestSlot",
    "NameAlreadyBound", "NameNotFound", "NameRegistry", "NamingError", "Overflow",
    "Parameters", "Publisher", "PublishServerReactor", "Reactor", "RestartPolicy", "Scan",
    "SerialSpec", "Servant", "StartupError", "State", "StreamDecoder", "SubscribePublishServer",
    "Subscription", "System", "TcpSpec", "TransportClosed", "VirtualClock", "WallClock",
    "memory_pipe", "param", "proxy_for",
]
