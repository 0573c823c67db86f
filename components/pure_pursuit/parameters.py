"""Pure Pursuit parameters, section ``PurePursuit``.

The seed says the algorithm "has no configurable parameters" (section 3.3.3). afa names
the events and interface it uses and the lookahead distance the seed leaves implicit;
every parameter here is an afa addition.

Units: ``-`` marks names.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from afa.config.parameters import Parameters, param

__all__ = ["PurePursuitParameters"]


class PurePursuitParameters(Parameters):
    """GPS waypoint following by Gaussian arc votes."""

    EventChannelName: str = param("EventChannel", unit="-",
                                  description="afa addition: the event channel's name")
    PoseEventName: str = param("Pose", unit="-",
                               description="afa addition: subscribed Pose event name")
    VoteEventName: str = param("ArcVote", unit="-",
                               description="afa addition: name of the ArcVote events published")
    InterfaceName: str = param(
        "PurePursuit", unit="-",
        description="afa addition: name the VehiclePlan waypoint interface (Table 24) is "
                    "registered under")
    PlatformName: str = param(
        "ModelService", unit="-",
        description="afa addition: name ModelServer's Platform interface is offered under "
                    "(asked once where GroundFrame lies on the vehicle)")
    GroundFrame: str = param(
        "Raptor: Front-BumperCenter", unit="-",
        description="afa addition: the frame on the ground under the front bumper: a "
                    "waypoint is reached when the rear axle or this point comes within "
                    "its tolerance, as the Global Map and FindPath judge it")
    Lookahead: Annotated[float, Field(gt=0)] = param(
        5.0, unit="m",
        description="afa addition: lookahead distance along the path to the goal point "
                    "(Coulter 1992); about 2.5 s of travel at the Raptor's 2 m/s")
