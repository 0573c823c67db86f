"""LogNotify: the recorder as a component a configuration enables (seed Figure 19).

A Launcher entry of type ``LogNotify`` with a section of ``Afa::LogNotifyParameters``
records the system it runs in, as ``afa run --record`` does, from the moment it starts::

    <section name="LogNotifyConfig">
      <parameter name="Afa::LogNotifyParameters">
        <parameter name="FileName" value="raptor.mcap"/>
        <parameter name="Events" value="Pose,Gps,Imu,Laser*"/>
      </parameter>
    </section>
    ... in the Launcher: Name LogNotify, Type LogNotify, Section LogNotifyConfig

Put it first in the Launcher to record every event. A restart of the component starts a
new file (``raptor.1.mcap``, ...) rather than overwriting the one it was writing.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

from pydantic import Field

from afa.component import SubscribePublishServer
from afa.config.parameters import Parameters, param
from afa.errors import ComponentError
from afa.log.recorder import COMPRESSIONS, Recorder
from afa.naming import join_name

__all__ = ["LogNotify", "LogNotifyParameters"]


class LogNotifyParameters(Parameters):
    """The recorder's settings (afa addition: the seed names LogNotify, not its table)."""

    namespace = "Afa"
    FileName: str = param("afa.mcap", unit="-", description="MCAP file to write (relative to "
                                                            "the configuration's folder)")
    Events: str = param("", unit="-", description="comma-separated event names or patterns "
                                                  "to record ('' = every event)")
    Compression: str = param("zstd", unit="-", description="zstd, lz4 or none")
    Viewer: bool = param(True, unit="-", description="also write Foxglove viewer channels")
    FlushPeriod: Annotated[float, Field(gt=0)] = param(
        1.0, unit="s", description="seconds between flushes (what a killed process keeps)")


class LogNotify(SubscribePublishServer[LogNotifyParameters]):
    """Records the system it belongs to (see the module docstring)."""

    def __init__(self, name: str, parameters: LogNotifyParameters | None = None) -> None:
        super().__init__(name, parameters)
        if self.parameters.Compression not in COMPRESSIONS:
            raise ComponentError(f"{name}: Compression {self.parameters.Compression!r} is not "
                                 f"one of {', '.join(COMPRESSIONS)}")
        self.recorder: Recorder | None = None

    async def setup(self) -> None:
        p = self.parameters
        # the system bound the event channel under its own ownership: that is the system
        system: Any = self.context.registry.owner(join_name(self.robot, "EventChannel"))
        if system is None or not hasattr(system, "observe"):
            raise ComponentError(f"{self.name}: not running inside a System")
        path = Path(p.FileName)
        if not path.is_absolute():
            path = self.context.base_dir / path
        if self.restarts:
            path = path.with_suffix(f".{self.restarts}{path.suffix}")
        events = [e.strip() for e in p.Events.split(",") if e.strip()] or None
        self.recorder = Recorder(path, events=events, compression=p.Compression,
                                 viewer=p.Viewer, flush_period=p.FlushPeriod)
        self.recorder.attach(system, metadata={"recorded_by": self.name})

    async def teardown(self) -> None:
        if self.recorder is not None:
            await self.recorder.close()
            self.recorder = None

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        if self.recorder is not None:
            stats.update(self.recorder.statistics())
        return stats
