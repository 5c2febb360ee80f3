"""The non-learned warm starts, now beside their families (kept for old imports).

* :class:`~scpformer.problems.rendezvous.warmstart.RendezvousConvexWarmStart`: Problems 1-2 of
  the ART paper;
* :class:`~scpformer.problems.robust_rendezvous.warmstart.RobustTpbvpWarmStart`: the robust
  family's convex TPBVP;
* :class:`~scpformer.problems.pdg6dof.warmstart.AnalyticWarmStart`: the 6-DoF analytic
  guesses.
"""

from scpformer.problems.pdg6dof.warmstart import AnalyticWarmStart
from scpformer.problems.rendezvous.warmstart import RENDEZVOUS_CONVEX, RendezvousConvexWarmStart
from scpformer.problems.robust_rendezvous.warmstart import RobustTpbvpWarmStart
from scpformer.scp.warmstart import check_instance

__all__ = [
    "RENDEZVOUS_CONVEX",
    "AnalyticWarmStart",
    "RendezvousConvexWarmStart",
    "RobustTpbvpWarmStart",
    "check_instance",
]
