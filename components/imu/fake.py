"""A fake MicroStrain 3DM-GX1: the device side of the IMU codec, for tests and simulation.

:class:`FakeImu` decodes host commands with :class:`~components.imu.codec.ImuDeviceDecoder`
and answers them with the codec's reply encoders, as the unit would: polls (0x31, 0x0E,
0x0D, 0x07, 0xF0, 0xF1), gyro bias capture (0x06, answered when the capture is done),
EEPROM reads and writes (0x28, 0x29; the gain words scale what it sends) and continuous
mode (0x10: the chosen reply repeated every ``period`` seconds until ``10 00 00``).

Physical values come from ``source(t) -> ImuTruth`` (t: clock seconds), so the
simulator can plug in its world; the default is a unit lying level and still. With a
seeded ``numpy.random.Generator`` the fake adds white noise (:class:`ImuNoise`) and a
constant gyro bias drawn once, which a 0x06 capture removes. Runs are deterministic for
a given seed and clock.

The unit keeps its state (continuous mode, EEPROM, bias) across connections, as a
powered device does when its cable is pulled: after ``unplug()`` / ``plug()`` it
resumes streaming at once, and the driver must stop it before its EEPROM reads.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from afa.clock import Clock
from afa.codec import StreamDecoder
from afa.fake import FakeDevice
from afa.transport import ByteStream
from components.imu.codec import (
    ACCEL_GAIN_SCALE_ADDRESS,
    CMD_CAPTURE_GYRO_BIAS,
    CMD_FIRMWARE_VERSION,
    CMD_GYRO_STAB_EULER,
    CMD_GYRO_STAB_EULER_ACCEL_RATE,
    CMD_INSTANT_EULER,
    CMD_SERIAL_NUMBER,
    CMD_TEMPERATURE,
    CONTINUOUS_COMMANDS,
    DEFAULT_ACCEL_GAIN_SCALE,
    DEFAULT_GYRO_GAIN_SCALE,
    DEFAULT_MAG_GAIN_SCALE,
    GYRO_GAIN_SCALE_ADDRESS,
    MAG_GAIN_SCALE_ADDRESS,
    STANDARD_GRAVITY,
    TIMER_TICK_SECONDS,
    GainScales,
    ImuCommand,
    ImuDeviceDecoder,
    PollCommand,
    ReadEepromCommand,
    SetContinuousCommand,
    WriteEepromCommand,
    encode_continuous_mode_set_reply,
    encode_eeprom_value_reply,
    encode_euler_accel_rate_reply,
    encode_euler_angles_reply,
    encode_firmware_version_reply,
    encode_gyro_bias_captured_reply,
    encode_serial_number_reply,
    encode_temperature_reply,
)

__all__ = ["FakeImu", "ImuTruth", "ImuNoise", "ImuSource", "level_and_still", "DEFAULT_PERIOD"]

Vector = tuple[float, float, float]

#: Continuous-mode report period: 100 Hz, the rate a 10 ms calculation cycle gives
#: (what the jage92 ROS driver programs). A factory unit's rate depends on its EEPROM
#: calculation-cycle words; the driver does not rely on it.
DEFAULT_PERIOD = 0.01


@dataclass(frozen=True, slots=True)
class ImuTruth:
    """What the unit senses: the ground truth a simulator provides.

    Angles in rad (the unit's gyro-stabilised roll, pitch, yaw), ``accel`` the specific
    force in m/s^2 (gravity included: a level unit at rest reads (0, 0, -g) in its
    z-down frame), ``rates`` in rad/s, ``temperature`` in degrees Celsius.
    """

    roll: float
    pitch: float
    yaw: float
    accel: Vector
    rates: Vector
    temperature: float = 25.0


ImuSource = Callable[[float], ImuTruth]


def level_and_still(t: float) -> ImuTruth:
    """The default source: level, heading 0, at rest."""
    return ImuTruth(0.0, 0.0, 0.0, (0.0, 0.0, -STANDARD_GRAVITY), (0.0, 0.0, 0.0))


@dataclass(frozen=True, slots=True)
class ImuNoise:
    """Standard deviations of the fake's white noise and of its constant gyro bias.

    Rate and accel noise follow from the random walks quoted for the 3DM-GX1
    (3.5 deg/sqrt(h), 0.4 m/s/sqrt(h)) over a 50 Hz bandwidth; the angle noise and
    the bias spread are plausible values, not datasheet figures.
    """

    angle: float = math.radians(0.1)  # rad
    accel: float = 0.047  # m/s^2
    rate: float = 0.0072  # rad/s
    gyro_bias: float = 0.01  # rad/s


class FakeImu(FakeDevice[ImuCommand]):
    """The device side of a 3DM-GX1 (see the module docstring).

    Args:
        clock: the clock whose time drives reports and timer ticks.
        source: ``source(t) -> ImuTruth``; default :func:`level_and_still`.
        rng: a seeded generator; None gives exact values (no noise, no bias).
        noise: noise levels used when ``rng`` is given (default :class:`ImuNoise`).
        period: continuous-mode report period in seconds.
        accel_gain, gyro_gain: the unit's EEPROM gain words.
        answers_eeprom: False makes the unit ignore EEPROM reads (an old firmware, a
            half-working line), to exercise the driver's fallback.
        bias_capture_seconds: how long a 0x06 capture takes before its reply.

    Raises:
        ValueError: ``period`` is not positive, or a gain is not in 1..32767.
    """

    name = "3DM-GX1"

    def __init__(
        self,
        clock: Clock,
        source: ImuSource = level_and_still,
        *,
        rng: np.random.Generator | None = None,
        noise: ImuNoise | None = None,
        period: float = DEFAULT_PERIOD,
        accel_gain: int = DEFAULT_ACCEL_GAIN_SCALE,
        gyro_gain: int = DEFAULT_GYRO_GAIN_SCALE,
        answers_eeprom: bool = True,
        firmware: int = 3104,
        serial_number: int = 1234,
        bias_capture_seconds: float = 10.0,
    ) -> None:
        super().__init__(clock)
        if not period > 0:
            raise ValueError(f"period must be positive, got {period}")
        GainScales(accel=accel_gain, gyro=gyro_gain)  # validates
        self.source = source
        self.rng = rng
        self.noise = noise if noise is not None else ImuNoise()
        self.period = period
        self.answers_eeprom = answers_eeprom
        self.firmware = firmware
        self.serial_number = serial_number
        self.bias_capture_seconds = bias_capture_seconds
        self._gains: tuple[tuple[int, int], GainScales] | None = None
        self.eeprom: dict[int, int] = {
            ACCEL_GAIN_SCALE_ADDRESS: accel_gain,
            GYRO_GAIN_SCALE_ADDRESS: gyro_gain,
            MAG_GAIN_SCALE_ADDRESS: DEFAULT_MAG_GAIN_SCALE,
        }
        self.gyro_bias: Vector = (
            (0.0, 0.0, 0.0) if rng is None
            else tuple(float(b) for b in rng.normal(0.0, self.noise.gyro_bias, 3)))  # type: ignore[assignment]
        #: The command repeated in continuous mode; 0: continuous mode off.
        self.continuous = 0
        #: Continuous reports sent (all connections).
        self.reports = 0
        self._power_on = clock.monotonic()
        self._pending: list[bytes] = []
        self._corrupt = 0

    # -- test and simulator controls -----------------------------------------------------
    def inject(self, data: bytes) -> None:
        """Send ``data`` raw, just before the next continuous report (line noise)."""
        self._pending.append(bytes(data))

    def corrupt_next(self, count: int = 1) -> None:
        """Flip one bit in each of the next ``count`` continuous reports."""
        self._corrupt += count

    @property
    def gains(self) -> GainScales:
        """The gain scales the unit's EEPROM words give (what its replies are scaled by)."""
        words = (self.eeprom[ACCEL_GAIN_SCALE_ADDRESS], self.eeprom[GYRO_GAIN_SCALE_ADDRESS])
        known = self._gains
        if known is None or known[0] != words:  # (asked for on every reply, 100 a second)
            known = self._gains = (words, GainScales(accel=_signed(words[0]),
                                                     gyro=_signed(words[1])))
        return known[1]

    def timer_ticks(self) -> int:
        """The free-running 16-bit TimerTicks counter now."""
        return int((self.clock.monotonic() - self._power_on) / TIMER_TICK_SECONDS) & 0xFFFF

    def measure(self) -> ImuTruth:
        """What the unit reports now: truth plus noise and gyro bias."""
        truth = self.source(self.clock.now())
        bias = self.gyro_bias
        if self.rng is None:
            rates = tuple(r + b for r, b in zip(truth.rates, bias, strict=True))
            return ImuTruth(truth.roll, truth.pitch, truth.yaw, truth.accel,
                            rates, truth.temperature)  # type: ignore[arg-type]
        n = self.noise
        # one draw for all nine: angles, accelerations, rates (a standard normal scaled)
        e = (self.rng.standard_normal(9) * (n.angle, n.angle, n.angle, n.accel, n.accel,
                                            n.accel, n.rate, n.rate, n.rate)).tolist()
        (ax, ay, az), (rx, ry, rz), (bx, by, bz) = truth.accel, truth.rates, bias
        return ImuTruth(truth.roll + e[0], truth.pitch + e[1], truth.yaw + e[2],
                        (ax + e[3], ay + e[4], az + e[5]),
                        (rx + bx + e[6], ry + by + e[7], rz + bz + e[8]), truth.temperature)

    def reply(self, command: int) -> bytes:
        """The unit's reply to the single-byte ``command`` now.

        Raises:
            ValueError: ``command`` is not a poll this fake answers.
        """
        ticks = self.timer_ticks()
        if command == CMD_GYRO_STAB_EULER_ACCEL_RATE:
            m = self.measure()
            return encode_euler_accel_rate_reply(m.roll, m.pitch, m.yaw, m.accel, m.rates,
                                                 ticks, self.gains)
        if command in (CMD_GYRO_STAB_EULER, CMD_INSTANT_EULER):
            m = self.measure()
            return encode_euler_angles_reply(m.roll, m.pitch, m.yaw, ticks,
                                             stabilised=command == CMD_GYRO_STAB_EULER)
        if command == CMD_TEMPERATURE:
            return encode_temperature_reply(self.source(self.clock.now()).temperature, ticks)
        if command == CMD_FIRMWARE_VERSION:
            return encode_firmware_version_reply(self.firmware)
        if command == CMD_SERIAL_NUMBER:
            return encode_serial_number_reply(self.serial_number)
        raise ValueError(f"the fake 3DM-GX1 does not answer 0x{command:02X}")

    # -- FakeDevice hooks ----------------------------------------------------------------
    def command_decoder(self) -> StreamDecoder[ImuCommand]:
        return ImuDeviceDecoder()

    async def on_command(self, command: ImuCommand, stream: ByteStream) -> None:
        ticks = self.timer_ticks()
        if isinstance(command, SetContinuousCommand):
            # 10 00 00 stops; the unit confirms either way (see the protocol doc).
            self.continuous = command.command if command.command in CONTINUOUS_COMMANDS else 0
            await stream.write(encode_continuous_mode_set_reply(command.command, ticks))
        elif isinstance(command, ReadEepromCommand):
            if self.answers_eeprom:
                value = self.eeprom.get(command.address, 0)
                await stream.write(encode_eeprom_value_reply(value, ticks))
        elif isinstance(command, WriteEepromCommand):
            self.eeprom[command.address] = command.value
            await stream.write(encode_eeprom_value_reply(command.value, ticks, written=True))
        elif isinstance(command, PollCommand):
            if command.command == CMD_CAPTURE_GYRO_BIAS:
                await self.clock.sleep(self.bias_capture_seconds)  # busy: keep still
                self.gyro_bias = (0.0, 0.0, 0.0)
                await stream.write(encode_gyro_bias_captured_reply(self.timer_ticks()))
            else:
                await stream.write(self.reply(command.command))

    async def produce(self, stream: ByteStream) -> None:
        async for _ in self.clock.periodic(self.period):
            if not self.continuous:
                continue
            frame = self.reply(self.continuous)
            if self._corrupt:
                self._corrupt -= 1
                corrupted = bytearray(frame)
                corrupted[3] ^= 0x10  # a data byte: the checksum no longer matches
                frame = bytes(corrupted)
            pending, self._pending = b"".join(self._pending), []
            await stream.write(pending + frame)
            self.reports += 1


def _signed(word: int) -> int:
    return word - 0x10000 if word & 0x8000 else word

