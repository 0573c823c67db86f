"""Vehicle Control (seed §3.5, Tables 26, 27, A.13) over the MPC555 link.

A Publish Server and Reactor sharing the serial port with Wheel Odometry
(``docs/protocols/mpc555.md``, "Driver" section for the decisions summarised here):

- Every Table 26 method sends the protocol's command and waits for its ACK. Mode and
  configuration commands are retransmitted (same SEQ) up to three times 50 ms apart;
  velocity commands are not (the next one supersedes them). A NAK, or no ACK after the
  retransmissions, raises :class:`~afa.errors.EDevIO` to the caller.
- Limits (``MaxTransVelocity`` mm/s, ``MaxRotVelocity`` rad/s, ``MaxSteeringAngle``
  deg) are enforced by **clamping**, not by ``EOutOfBounds``: see :func:`clamp_velocity`.
- Arbiter semantics: ``setArbiter(false)`` (the state after start-up and after a
  controller reset) means ``setVelocity`` calls, the Arc Arbiter's path, are ignored
  (counted, not sent) while ``setJoystickVelocity`` is obeyed. With the arbiter on,
  ``setVelocity`` is obeyed, and a joystick command still takes over (the controller's
  JOYSTICK override) until ``setArbiter`` or ``startVehicle`` ends the override.
- A HEARTBEAT goes out whenever no frame was sent for 100 ms; while the link is silent
  after a (re)connection, STOP_VEHICLE goes out in its place.
- Host command watchdog (``CommandWatchdog``, 0.5 s): armed by the first velocity
  command after ``startVehicle``; when no further ``setVelocity`` /
  ``setJoystickVelocity`` is obeyed for that long it sends STOP_VEHICLE and says so in
  the component's health detail.
- VelocityData events (Table 27) are published under ``RaptorMotionEvent`` for every
  SPEED report; the Table 26 interface is bound under the same name.
"""

from __future__ import annotations

import asyncio
import logging
import math
from dataclasses import dataclass
from typing import Any

from afa.errors import ComponentError, EDevIO, ETimeOut
from components.mpc555.codec import (
    MAX_PEDAL_POINTS,
    MIN_STEER_SPEED_MM_S,
    Command,
    Heartbeat,
    Mode,
    PedalBreakpoint,
    Report,
    SetArbiter,
    SetJoystickVelocity,
    SetLimits,
    SetPedalCalibration,
    SetSteerPid,
    SetVelocity,
    SpeedReport,
    StartVehicle,
    StatusFlags,
    StatusReport,
    StopVehicle,
    steering_angle,
)
from components.mpc555.odometry import (
    STATUS_INTERVAL_MS,
    Mpc555Host,
    link_timeout,
    steer_calibration,
    wheel_calibration,
)
from components.mpc555.parameters import VehicleControlParameters
from idl import MinMaxVelocityIDL, TimeIDL, VelocityDataIDL, VelocityIDL
from idl import VehicleControl as VehicleControlInterface

__all__ = ["VehicleControl", "MotionLimits", "ClampedVelocity", "clamp_velocity",
           "HEARTBEAT_INTERVAL"]

HEARTBEAT_INTERVAL = 0.100
"""Seconds without a host frame after which a HEARTBEAT is sent (protocol: 100 ms)."""
READY_WAIT = 1.0
"""Seconds a command waits for the start-up configuration to finish before EDevIO."""
_CONTROLLER_DEFAULT_WHEEL_MS = 200
_CONTROLLER_DEFAULT_SPEED_MS = 1000
_I16 = 32767


@dataclass(frozen=True)
class MotionLimits:
    """The accepted velocity ranges, SI units (from Table A.13's parameters)."""

    min_translation: float  # m/s (reverse, negative)
    max_translation: float  # m/s
    max_rotation: float  # rad/s, either side
    max_steering: float  # rad, either side
    wheelbase: float  # m

    @classmethod
    def from_parameters(cls, p: VehicleControlParameters) -> MotionLimits:
        """``MaxTransVelocity`` (mm/s), narrowed to the pedal table's velocity range (the
        controller cannot command beyond its end breakpoints) and to the int16 wire
        field; ``MaxRotVelocity`` (rad/s); ``MaxSteeringAngle`` (deg)."""
        velocities = [point.Velocity for point in p.PedalParam]
        top = min(p.MaxTransVelocity, max(velocities), _I16)
        bottom = max(-p.MaxTransVelocity, min(velocities), -_I16)
        return cls(bottom / 1000.0, top / 1000.0, min(p.MaxRotVelocity, _I16 / 1000.0),
                   math.radians(p.MaxSteeringAngle), p.Wheelbase)

    def as_idl(self) -> MinMaxVelocityIDL:
        return MinMaxVelocityIDL(minTranslation=self.min_translation,
                                 maxTranslation=self.max_translation,
                                 minRotation=-self.max_rotation, maxRotation=self.max_rotation,
                                 maxSteeringAngle=self.max_steering)


@dataclass(frozen=True)
class ClampedVelocity:
    """A velocity request after the limits: the wire values and the resulting target."""

    translation_mm_s: int
    rotation_mrad_s: int
    target: VelocityIDL
    limited: bool


def _clamp(value: float, low: float, high: float) -> float:
    return min(max(value, low), high)


def clamp_velocity(velocity: VelocityIDL, limits: MotionLimits,
                   present_steering: float = 0.0) -> ClampedVelocity:
    """Turn a ``VelocityIDL`` request into SET_VELOCITY wire values within ``limits``.

    A non-zero ``steeringAngle`` is the request's curvature (rotation is then
    ``v·tan δ / L``); otherwise ``rotation`` is. Translation is clamped to
    [min, max], rotation to ±max, then the bicycle-model steering angle
    ``atan(L·ω/v)`` to ±max steering (rotation recomputed from the clamped angle, and
    rounded so that the controller does not clamp again). Below 10 mm/s the
    curvature is undefined and the controller keeps ``present_steering``.

    Clamping rather than raising EOutOfBounds: arbiter and joystick outputs are
    continuous controls for which saturation is the expected actuator behaviour, and an
    exception would leave the previous (possibly faster) command in force, whereas the
    clamped command still slows or steers the vehicle as far as allowed. ``limited``
    says a clamp applied; Vehicle Control counts it.
    """
    v = _clamp(velocity.translation, limits.min_translation, limits.max_translation)
    limited = v != velocity.translation
    L = limits.wheelbase
    if velocity.steeringAngle != 0.0:
        requested = velocity.steeringAngle
        if abs(requested) > limits.max_steering:
            requested = math.copysign(limits.max_steering, requested)
            limited = True
        w = v * math.tan(requested) / L
    else:
        w = velocity.rotation
    clamped_w = _clamp(w, -limits.max_rotation, limits.max_rotation)
    limited = limited or clamped_w != w
    w = clamped_w
    translation_mm_s = round(v * 1000.0)
    if abs(translation_mm_s) < MIN_STEER_SPEED_MM_S:
        return ClampedVelocity(translation_mm_s, round(w * 1000.0), VelocityIDL(
            translation=translation_mm_s / 1000.0, rotation=round(w * 1000.0) / 1000.0,
            steeringAngle=present_steering), limited)
    steering = math.atan(L * w / v)
    if abs(steering) > limits.max_steering:
        steering = math.copysign(limits.max_steering, steering)
        w = v * math.tan(steering) / L
        limited = True
    rotation_mrad_s = round(w * 1000.0)
    # Rounding must not push the angle the controller computes from the wire values
    # over its limit (it would clamp again and answer LIMITED): step toward zero.
    wheelbase_mm = round(L * 1000.0)
    wire_limit = math.radians(round(math.degrees(limits.max_steering) * 100.0) / 100.0)
    while rotation_mrad_s and abs(steering_angle(  # type: ignore[arg-type]
            translation_mm_s, rotation_mrad_s, wheelbase_mm)) > wire_limit:
        rotation_mrad_s -= 1 if rotation_mrad_s > 0 else -1
    target = VelocityIDL(translation=translation_mm_s / 1000.0,
                         rotation=rotation_mrad_s / 1000.0, steeringAngle=steering)
    return ClampedVelocity(translation_mm_s, rotation_mrad_s, target, limited)


class VehicleControl(Mpc555Host[VehicleControlParameters]):
    """The Vehicle Control component (seed §3.5); see the module docstring."""

    seq_start = 0

    def __init__(self, name: str, parameters: VehicleControlParameters | None = None) -> None:
        super().__init__(name, parameters)
        p = self.parameters
        if len(p.PedalParam) > MAX_PEDAL_POINTS:
            raise ComponentError(f"{name}: PedalParam has {len(p.PedalParam)} breakpoints; "
                                 f"the MPC555 link carries at most {MAX_PEDAL_POINTS}")
        # The controller's default intervals; STATUS (500 ms) bounds the gap between
        # frames whatever WheelDistRepTime Wheel Odometry configures.
        self.stale_after = link_timeout(_CONTROLLER_DEFAULT_WHEEL_MS,
                                        _CONTROLLER_DEFAULT_SPEED_MS, STATUS_INTERVAL_MS)
        self.events = self.publishes(p.RaptorMotionEvent, VelocityDataIDL)
        self.serves(VehicleControlInterface, p.RaptorMotionEvent)
        self.limits = MotionLimits.from_parameters(p)
        self.control_counters: dict[str, int] = dict.fromkeys(
            ("velocity_commands", "ignored_velocity_commands", "limited_commands",
             "watchdog_stops", "heartbeats", "link_lost_stops"), 0)
        self._reset_state()

    def _reset_state(self) -> None:
        self.started = False
        self.arbiter_enabled = False
        self.joystick_override = False
        self.last_status: StatusReport | None = None
        self.last_velocity_data: VelocityDataIDL | None = None
        self._target = VelocityIDL()
        self._last_motion: float | None = None  # the command watchdog is armed when set

    async def setup(self) -> None:
        await super().setup()
        self._reset_state()
        self._motion = asyncio.Event()
        self.spawn(self._heartbeat(), f"{self.name}:heartbeat")
        self.spawn(self._command_watchdog(), f"{self.name}:command-watchdog")

    def configuration(self) -> list[Command]:
        p = self.parameters
        return [
            SetLimits(min(round(p.MaxTransVelocity), _I16),
                      min(round(p.MaxRotVelocity * 1000.0), _I16),
                      min(round(p.MaxSteeringAngle * 100.0), 0xFFFF),
                      min(round(p.Wheelbase * 1000.0), 0xFFFF)),
            wheel_calibration(p.LfdParam, p.RfdParam),
            steer_calibration(p.SteerParam),
            SetPedalCalibration(tuple(
                PedalBreakpoint(round(_clamp(point.Velocity, -_I16, _I16)), point.Command)
                for point in p.PedalParam)),
            SetSteerPid(round(p.SteerPID.P * 1000.0), round(p.SteerPID.I * 1000.0),
                        round(p.SteerPID.D * 1000.0)),
        ]

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats.update(self.control_counters)
        return stats

    # -- reports -------------------------------------------------------------------------
    def on_controller_reset(self) -> None:
        self._stopped()
        self.arbiter_enabled = False
        self.joystick_override = False

    def on_report(self, report: Report) -> None:
        if isinstance(report, SpeedReport):
            self._publish_velocity(report)
        elif isinstance(report, StatusReport):
            self._status(report)
        # WHEEL_DISTANCE belongs to Wheel Odometry.

    def _status(self, status: StatusReport) -> None:
        previous, self.last_status = self.last_status, status
        self.arbiter_enabled = StatusFlags.ARBITER_ENABLED in status.flags
        self.joystick_override = status.mode is Mode.JOYSTICK
        if status.mode is Mode.STOPPED:
            self._stopped()
        else:
            self.started = True
        watchdog = StatusFlags.WATCHDOG in status.flags
        if watchdog and (previous is None or StatusFlags.WATCHDOG not in previous.flags):
            self._note("the MPC555 link watchdog stopped the vehicle (no host frame for "
                       "500 ms); startVehicle() to resume")
        if (StatusFlags.CALIBRATED not in status.flags and self.configured
                and not self.configuring):
            self.log.warning("MPC555 lost its calibration: configuring again")
            self.configured = False
            self._start_configuration()

    def _publish_velocity(self, report: SpeedReport) -> None:
        steering = math.radians(report.steering_cdeg / 100.0)
        front = report.speed_mm_s / 1000.0  # mean of the front wheels
        # The front wheels roll along their heading: the rear-axle (reference) speed is
        # v_front·cos δ and the bicycle-model yaw rate v_front·sin δ / L.
        body = VelocityDataIDL(
            time=TimeIDL.from_seconds(self.clock.now()),
            velocity=VelocityIDL(translation=front * math.cos(steering),
                                 rotation=front * math.sin(steering) / self.limits.wheelbase,
                                 steeringAngle=steering),
            target=self._target,
            vehicleStarted=self.started,
            arbiterEnabled=self.arbiter_enabled,
        )
        self.last_velocity_data = body
        self.events.publish(body)

    # -- helpers -------------------------------------------------------------------------
    def _stopped(self) -> None:
        self.started = False
        self.joystick_override = False
        self._target = VelocityIDL(steeringAngle=self._target.steeringAngle)
        self._last_motion = None

    def _note(self, detail: str) -> None:
        """Set the health detail, keeping the healthy flag (the link may be fine)."""
        self.set_health(self._healthy, detail)

    async def _require_link(self) -> None:
        """Raise EDevIO unless the link is up and configured. A connection or
        configuration in progress (just after start-up or a reconnection) is waited for,
        up to ``READY_WAIT`` seconds."""
        connected = self.reactor is not None and self.reactor.connected
        if not (connected and self.configured):
            try:
                async with self.clock.timeout(READY_WAIT, "MPC555 configuration"):
                    await self.ready.wait()
            except ETimeOut:
                pass
        if self.reactor is None or not self.reactor.connected:
            raise EDevIO(f"{self.name}: the MPC555 link is down")
        if not self.configured:
            raise EDevIO(f"{self.name}: the MPC555 is not configured")
        if not self.link_up:
            raise EDevIO(f"{self.name}: no report from the MPC555 since reconnecting")

    async def _drive(self, joystick: bool, velocity: VelocityIDL) -> None:
        await self._require_link()
        clamped = clamp_velocity(velocity, self.limits, self._target.steeringAngle)
        if clamped.limited:
            self.control_counters["limited_commands"] += 1
            self.log.debug("velocity request %s clamped to %s", velocity, clamped.target)
        kind = SetJoystickVelocity if joystick else SetVelocity
        await self.command(kind(clamped.translation_mm_s, clamped.rotation_mrad_s), retries=0)
        self.control_counters["velocity_commands"] += 1
        self._target = clamped.target
        if joystick:
            self.joystick_override = True
        self._last_motion = self.clock.monotonic()
        self._motion.set()

    # -- background tasks ----------------------------------------------------------------
    async def _heartbeat(self) -> None:
        """HEARTBEAT after 100 ms without a frame; STOP_VEHICLE instead while the link
        is silent after a (re)connection."""
        clock = self.clock
        while True:
            now = clock.monotonic()
            if self.last_tx is not None and now < self.last_tx + HEARTBEAT_INTERVAL:
                await clock.sleep_until(self.last_tx + HEARTBEAT_INTERVAL)
                continue
            if self.reactor is None or not self.reactor.connected:
                await clock.sleep(HEARTBEAT_INTERVAL)
                continue
            silent = not self.link_up
            try:
                await self.send_unacknowledged(StopVehicle() if silent else Heartbeat())
            except EDevIO:
                await clock.sleep(HEARTBEAT_INTERVAL)
                continue
            self.control_counters["link_lost_stops" if silent else "heartbeats"] += 1

    async def _command_watchdog(self) -> None:
        """Stop the vehicle when the velocity commands stop coming."""
        interval = self.parameters.CommandWatchdog
        while True:
            last = self._last_motion
            if last is None:
                self._motion.clear()
                await self._motion.wait()
                continue
            if self.clock.monotonic() < last + interval:
                await self.clock.sleep_until(last + interval)
                continue
            self.control_counters["watchdog_stops"] += 1
            # at rest as commanded (the end of a drive or a mission), the stop is routine;
            # commands that stop while the vehicle was told to move are a fault upstream
            routine = self._target.translation == 0.0
            self._stopped()
            detail = (f"command watchdog: no velocity command for {interval:g} s, "
                      "vehicle stopped" + (" (it was at rest)" if routine else ""))
            try:
                await self.command(StopVehicle())
            except EDevIO as exc:
                detail += f" (STOP_VEHICLE failed: {exc})"
                routine = False
            self.log.log(logging.INFO if routine else logging.WARNING, "%s", detail)
            self._note(detail)

    # -- VehicleControl interface (Table 26) ---------------------------------------------
    async def setVelocity(self, velocity: VelocityIDL) -> None:
        """Command a velocity (the Arc Arbiter's call); clamped to the limits.

        Ignored (counted, not sent) while the arbiter is off or a joystick override is
        on. Raises EDevIO when the link is down or the controller refuses it (e.g.
        NOT_RUNNING before startVehicle) or does not acknowledge it within 50 ms.
        """
        if not self.arbiter_enabled or self.joystick_override:
            self.control_counters["ignored_velocity_commands"] += 1
            return
        await self._drive(False, velocity)

    async def getTargetVelocity(self) -> VelocityIDL:
        """The velocity last commanded (after clamping); zero speed when stopped."""
        return self._target

    async def startVehicle(self) -> None:
        """Release the brake and accept motion commands (target 0).

        Raises EDevIO when the link is down or not configured, or when the controller
        refuses (ESTOP, NOT_CALIBRATED, FAULT) or does not acknowledge it.
        """
        await self._require_link()
        await self.command(StartVehicle())
        self.started = True
        self.joystick_override = False
        self._target = VelocityIDL(steeringAngle=self._target.steeringAngle)
        self._last_motion = None
        self._note("connected, configured, vehicle started")

    async def stopVehicle(self) -> None:
        """Pedal to neutral and brake; velocity commands are refused until startVehicle.

        Raises EDevIO when the device is not connected or the controller does not
        acknowledge the stop after three retransmissions.
        """
        self._stopped()
        await self.command(StopVehicle())

    async def setJoystickVelocity(self, velocity: VelocityIDL) -> None:
        """Command a velocity from the operator's joystick (obeyed with the arbiter on or
        off; it takes over from the arbiter). Raises EDevIO as :meth:`setVelocity`."""
        await self._drive(True, velocity)

    async def setArbiter(self, enabled: bool) -> None:
        """Let the Arc Arbiter's ``setVelocity`` drive (true) or ignore it (false); ends a
        joystick override. Raises EDevIO on a NAK, no ACK, or no connection."""
        await self.command(SetArbiter(enabled))
        if self.joystick_override:
            self._target = VelocityIDL(steeringAngle=self._target.steeringAngle)
        self.arbiter_enabled = enabled
        self.joystick_override = False

    async def getMinMaxVelocity(self) -> MinMaxVelocityIDL:
        """The translation, rotation and steering ranges requests are clamped to."""
        return self.limits.as_idl()
