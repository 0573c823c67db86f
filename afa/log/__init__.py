"""Record and replay (the seed's LogNotify and LogPlayer) on MCAP files.

- :class:`Recorder`: an observer writing every event, every poll and viewer channels
  (Foxglove schemas) to an MCAP file, flushed every second (``afa run --record``, the
  LogNotify component).
- :class:`LogReader`: reads a recording, also one cut off by a killed process, and
  reports what it cannot read (:class:`LogError` for a file it cannot read at all).
- :class:`Player`: publishes a recording into a System built from a configuration, whose
  processing components run on it, answers the recorded servers' polls, and is driven
  by pause, resume, step, seek and speed (``afa replay``).
- :func:`check`: re-runs the processing components in virtual time and compares every
  output with the recorded one, stopping at the first divergence (``afa replay --check``).

Needs the optional extra ``log`` (the ``mcap`` package): ``pip install 'afa[log]'``.
The file layout is in :mod:`afa.log.format` and ``docs/logs.md``.
"""

from afa.log.check import CheckReport, Divergence, first_difference
from afa.log.format import DroppedIDL, PollCallIDL
from afa.log.player import Player, ReplayServant, check
from afa.log.reader import LogChannel, LogError, LogMessage, LogReader, recover
from afa.log.recorder import Recorder

__all__ = ["Recorder", "LogReader", "LogError", "LogChannel", "LogMessage", "recover",
           "Player", "ReplayServant", "check", "CheckReport", "Divergence",
           "first_difference", "PollCallIDL", "DroppedIDL"]
