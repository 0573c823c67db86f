"""The IMU component: a MicroStrain 3DM-GX1 on a serial port (seed §3.1.3, Tables 5, 6).

A Publish Server and Reactor: the reactor owns the serial line and the
:class:`~components.imu.codec.ImuDecoder`; this class turns each 0x31 reply (gyro-
stabilised Euler angles, acceleration and angular rate) into an :class:`~idl.ImuIDL`,
keeps it for ``getImuData`` / ``getWaitImuData`` and publishes ``Raptor/<EventName>``
every 100 ms (the seed's rate).

Start-up dialogue, at every (re)connection (``on_connect``):

1. ``10 00 00`` stops continuous mode (a unit left streaming by a previous run), then
   whatever the unit still sends is discarded until the line has been quiet for
   :data:`QUIET_TIME` (the tail of a stream, the reply to the stop, if any);
2. ``28 00 E6`` and ``28 00 82`` read AccelGainScale and GyroGainScale from EEPROM; if
   the unit does not answer within :data:`EEPROM_REPLY_TIMEOUT` the manual's defaults
   (7000, 8500) are used and a warning is logged;
3. ``10 00 31`` starts continuous mode: the unit repeats the 0x31 reply at its own
   calculation rate.

Publication rate: the unit streams faster than the seed's 100 ms (its rate is set by
calculation-cycle EEPROM words we do not rewrite). Every sample updates the polled
value; events are *decimated in time*: a sample is published when it is the first one
at or after the next slot of a 100 ms grid (``PUBLISH_PERIOD``), so events are 100 ms
apart on average whatever the unit's rate, and no sample is ever published twice. See
``docs/protocols/imu_3dmgx1.md``, "Driver".
"""

from __future__ import annotations

import functools
from typing import Any, ClassVar

from afa.codec import StreamDecoder
from afa.component import PublishServerReactor
from afa.errors import ETimeOut
from afa.polling import LatestSlot
from afa.reactor import Backoff
from afa.transport import ByteStream, DeviceSpec, SerialSpec
from components.imu.codec import (
    ACCEL_GAIN_SCALE_ADDRESS,
    CMD_GYRO_STAB_EULER_ACCEL_RATE,
    CMD_READ_EEPROM,
    CMD_SET_CONTINUOUS,
    DEFAULT_ACCEL_GAIN_SCALE,
    DEFAULT_GYRO_GAIN_SCALE,
    GYRO_GAIN_SCALE_ADDRESS,
    ContinuousModeSet,
    EepromValue,
    EulerAccelRate,
    GainScales,
    ImuDecoder,
    ImuReply,
    encode_read_eeprom,
    encode_set_continuous,
    encode_stop_continuous,
)
from components.imu.parameters import ImuParameters
from idl import Imu as ImuInterface
from idl import ImuIDL, TimeIDL

__all__ = ["Imu", "EEPROM_REPLY_TIMEOUT", "PUBLISH_PERIOD", "PUBLISH_TOLERANCE", "QUIET_TIME",
           "DRAIN_LIMIT", "imu_idl"]

#: The seed's publication period (Table 5: ImuIDL every 100 msec).
PUBLISH_PERIOD = 0.1
#: A sample this much before a grid slot still takes it, so the jitter of a serial
#: line never makes a slot wait for the following sample.
PUBLISH_TOLERANCE = 0.001
#: Silence that ends the discarding of old output after the stop command, and the
#: longest the discarding may last (a unit that ignores the stop keeps talking).
QUIET_TIME = 0.05
DRAIN_LIMIT = 0.5
#: How long to wait for each EEPROM reply before falling back to the default gains.
#: A 7-byte reply takes 1.8 ms at 38400 baud; 0.5 s is generous.
EEPROM_REPLY_TIMEOUT = 0.5


def imu_idl(sample: EulerAccelRate, time: float) -> ImuIDL:
    """The IDL event of one 0x31 sample received at ``time`` (clock seconds).

    Values stay in the sensor frame (``Imu:SensorCenter``); ModelServer maps them to
    the vehicle. Raises ValueError for a non-finite ``time``.
    """
    return ImuIDL(
        time=TimeIDL.from_seconds(time),
        roll=sample.roll,
        pitch=sample.pitch,
        yaw=sample.yaw,
        accelX=sample.accel_x,
        accelY=sample.accel_y,
        accelZ=sample.accel_z,
        rateX=sample.rate_x,
        rateY=sample.rate_y,
        rateZ=sample.rate_z,
    )


class Imu(PublishServerReactor[ImuParameters, ImuReply]):
    """The Raptor's IMU component (seed §3.1.3); serves the ``Imu`` interface.

    Polls: ``getImuData`` (latest sample; EDevIO before the first one) and
    ``getWaitImuData`` (next sample; ETimeOut after ``Imu.wait_timeout``). With
    ``Notify`` false no events are published but polls are answered.
    """

    #: No sample for 1 s (the unit streams at tens of Hz) means the device is lost.
    stale_after = 1.0
    backoff: ClassVar[Backoff] = Backoff(initial=0.2, factor=2.0, maximum=5.0)

    def __init__(self, name: str = "Imu", parameters: ImuParameters | None = None) -> None:
        super().__init__(name, parameters)
        p = self.parameters
        self._events = self.publishes(p.EventName, ImuIDL, enabled=p.Notify)
        self.serves(ImuInterface, p.EventName)
        self._replies = ImuDecoder(accept={CMD_GYRO_STAB_EULER_ACCEL_RATE, CMD_SET_CONTINUOUS,
                                           CMD_READ_EEPROM})
        self._latest: LatestSlot[ImuIDL] | None = None
        self._grid_start: float | None = None
        self._grid_slot = 0
        self.samples = 0
        self.published = 0
        self.gains_from_eeprom = False

    # -- PSR hooks ---------------------------------------------------------------------
    async def setup(self) -> None:
        self._latest = self.slot("IMU sample")

    def device(self) -> DeviceSpec:
        return SerialSpec(self.parameters.Device, self.parameters.Baudrate)

    def decoder(self) -> StreamDecoder[ImuReply]:
        return self._replies

    async def on_connect(self, stream: ByteStream) -> None:
        """Stop continuous mode, read the gains, start continuous 0x31 mode.

        Raises EDevIO (from the stream) if the device goes away meanwhile; the reactor
        then reconnects.
        """
        self._grid_start = None
        await stream.write(encode_stop_continuous())
        await self._drain(stream)
        accel = await self._read_eeprom(stream, ACCEL_GAIN_SCALE_ADDRESS)
        gyro = None if accel is None else await self._read_eeprom(stream, GYRO_GAIN_SCALE_ADDRESS)
        self._replies.gains = self._gains(accel, gyro)
        await stream.write(encode_set_continuous(CMD_GYRO_STAB_EULER_ACCEL_RATE))

    def handle(self, message: ImuReply) -> None:
        if isinstance(message, EulerAccelRate):
            now = self.clock.now()
            self.samples += 1
            assert self._latest is not None
            if self._events.enabled and self._due(self.clock.monotonic()):
                body = imu_idl(message, now)
                self._latest.set(body)
                self._events.publish(body)
                self.published += 1
            else:  # 100 samples a second, one in ten published: the rest built if polled
                self._latest.set_lazy(functools.partial(imu_idl, message, now))
        elif isinstance(message, ContinuousModeSet):
            if message.command not in (CMD_GYRO_STAB_EULER_ACCEL_RATE, 0x00):
                self.log.warning("continuous mode set to 0x%02X, expected 0x31", message.command)
        else:
            self.log.debug("ignoring %s", message)

    # -- polls (idl.Imu) ---------------------------------------------------------------
    async def getImuData(self) -> ImuIDL:
        """The latest sample; raises EDevIO if none has been received yet."""
        assert self._latest is not None
        return self._latest.get()

    async def getWaitImuData(self) -> ImuIDL:
        """The next sample; raises ETimeOut after ``Imu.wait_timeout`` seconds."""
        assert self._latest is not None
        return await self._latest.wait_next(ImuInterface.wait_timeout)

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats.update(samples=self.samples, published=self.published,
                     accel_gain_scale=self._replies.gains.accel,
                     gyro_gain_scale=self._replies.gains.gyro,
                     gains_from_eeprom=self.gains_from_eeprom)
        return stats

    # -- internals ---------------------------------------------------------------------
    async def _drain(self, stream: ByteStream) -> None:
        """Discard input until the line is quiet for QUIET_TIME (at most DRAIN_LIMIT)."""
        deadline = self.clock.monotonic() + DRAIN_LIMIT
        discarded = 0
        while self.clock.monotonic() < deadline:
            try:
                async with self.clock.timeout(QUIET_TIME, "quiet line"):
                    discarded += len(await stream.read())
            except ETimeOut:
                break
        self._replies.reset()
        if discarded:
            self.log.debug("discarded %d bytes after stopping continuous mode", discarded)

    async def _read_eeprom(self, stream: ByteStream, address: int) -> int | None:
        """Ask for one EEPROM word and wait for its reply; None after the timeout.

        Replies other than an EEPROM read (the tail of a previous continuous stream,
        the reply to the stop command) are skipped. The reply does not carry the
        address, so only one read is ever outstanding.
        """
        await stream.write(encode_read_eeprom(address))
        try:
            async with self.clock.timeout(EEPROM_REPLY_TIMEOUT, f"EEPROM word {address}"):
                while True:
                    for reply in self._replies.feed(await stream.read()):
                        if isinstance(reply, EepromValue) and not reply.written:
                            return reply.signed_value
                        self.log.debug("skipping %s while reading EEPROM", type(reply).__name__)
        except ETimeOut:
            return None

    def _gains(self, accel: int | None, gyro: int | None) -> GainScales:
        self.gains_from_eeprom = False
        if accel is None or gyro is None:
            self.log.warning(
                "no EEPROM reply within %g s; using the manual's default gains "
                "(AccelGainScale %d, GyroGainScale %d)", EEPROM_REPLY_TIMEOUT,
                DEFAULT_ACCEL_GAIN_SCALE, DEFAULT_GYRO_GAIN_SCALE)
            return GainScales()
        try:
            gains = GainScales(accel=accel, gyro=gyro)
        except ValueError as exc:
            self.log.warning("implausible EEPROM gains (%s); using the manual's defaults", exc)
            return GainScales()
        self.gains_from_eeprom = True
        self.log.info("gains from EEPROM: AccelGainScale %d, GyroGainScale %d", accel, gyro)
        return gains

    def _due(self, now: float) -> bool:
        """Whether the sample received at ``now`` takes the next 100 ms slot.

        The grid restarts at the first sample after a connect or after a gap longer
        than a whole period, so a stream that resumes does not publish a burst.
        """
        start = self._grid_start
        if start is None or now >= start + (self._grid_slot + 1) * PUBLISH_PERIOD:
            self._grid_start, self._grid_slot = now, 1
            return True
        if now >= start + self._grid_slot * PUBLISH_PERIOD - PUBLISH_TOLERANCE:
            self._grid_slot += 1
            return True
        return False
