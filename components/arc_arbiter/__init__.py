"""Arc Arbiter (seed §3.4): weighted votes, vetoes, certainty, max speed."""

from afa.registry import not_implemented
from components.arc_arbiter.parameters import ArcArbiterParameters

ArcArbiter = not_implemented("ArcArbiter", ArcArbiterParameters,
                             "Arc Arbiter: the decision-making capability")

__all__ = ["ArcArbiter", "ArcArbiterParameters"]
