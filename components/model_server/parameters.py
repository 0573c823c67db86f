"""ModelServer parameters: seed Table A.8, section ``ModelServer``.

The seed prints each name list as a flat run of words ("Gps Gps Imu Imu"), read as
(IDL-type, name) pairs; here each pair is a ``NameBinding`` struct, and each list a Miro
vector of unnamed structs::

    <parameter name="Subscriptions">
      <parameter>
        <parameter name="Type" value="Gps"/>
        <parameter name="Name" value="Gps"/>
      </parameter>
      <parameter> ... Imu Imu ... </parameter>
    </parameter>

Units: ``-`` marks names and flags.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from afa.config.parameters import Parameters, param

__all__ = ["ModelServerParameters", "EventChannelNames", "NameBinding"]


class NameBinding(Parameters):
    """One (IDL-type, name) pair of Table A.8."""

    Type: str = param(unit="-", description="IDL type, as the seed names it (Gps, Imu, Pose, "
                                            "Platform)")
    Name: str = param(unit="-", description="Event name, or naming-service name for "
                                            "resolved and offered objects")


class EventChannelNames(Parameters):
    """Names ModelServer subscribes to, publishes, resolves and offers (Table A.8)."""

    Subscriptions: list[NameBinding] = param(
        [NameBinding(Type="Gps", Name="Gps"), NameBinding(Type="Imu", Name="Imu")], unit="-",
        description="IDL-type EventName: events the pose filter consumes (Table 20 also "
                    "lists odometry, which the seed's default does not subscribe to)")
    Publications: list[NameBinding] = param(
        [NameBinding(Type="Pose", Name="Pose")], unit="-",
        description="IDL-type EventName: events published (PoseTransformIDL)")
    ResolvedNames: list[NameBinding] = param(
        [NameBinding(Type="Imu", Name="Imu")], unit="-",
        description="IDL-type EventName: objects resolved in the naming service (the "
                    "IMU, polled for bias capture)")
    OfferedNames: list[NameBinding] = param(
        [NameBinding(Type="Platform", Name="ModelService")], unit="-",
        description="IDL-type EventName: objects offered to clients (the Platform geometry "
                    "interface, Table 19)")


class ModelServerParameters(Parameters):
    """Geometry database and pose filter (seed Table A.8)."""

    EventChannelDescription: EventChannelNames = param(
        EventChannelNames(), unit="-",
        description="Subscribed, published, resolved and offered names with their IDL types")
    UseRawPose: bool = param(True, unit="-", description="don't use filtering")
    ModelFileName: str = param(
        "050917raptor01.XML", unit="-",
        description="name of geometry model file (the assembly file; a relative name is "
                    "taken relative to the configuration file's directory)")
    UpdatePeriod: Annotated[int, Field(ge=0)] = param(
        0, unit="ms",
        description="0: event driven, > 0: timed updates (the period in milliseconds "
                    "between Pose events, seed section 3.2.4)")
    FidgetDelay: Annotated[float, Field(ge=0)] = param(
        20.0, unit="s",
        description="delay before fidgeting (stationary time before IMU bias capture "
                    "starts; the seed gives no unit, afa reads seconds)")
    FidgetPeriod: Annotated[float, Field(gt=0)] = param(
        300.0, unit="s",
        description="period between fidgets (bias captures while stationary; the seed "
                    "gives no unit, afa reads seconds)")
