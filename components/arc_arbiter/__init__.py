"""Arc Arbiter (seed §3.4): weighted votes, vetoes, certainty, max speed."""

from components.arc_arbiter.component import ArcArbiter
from components.arc_arbiter.parameters import ArcArbiterParameters

__all__ = ["ArcArbiter", "ArcArbiterParameters"]
