"""The analytic warm starts of the 6-DoF problem behind the warm-start interface.

The cubic profile (the solver's default cold start) and the straight line (Szmuk & Acikmese
2018, Sec. IV), named as in :data:`~scpformer.problems.pdg6dof.guess.ANALYTIC_GUESSES`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

from scpformer.problems.pdg6dof.guess import ANALYTIC_GUESSES
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.scp.warmstart import WarmStartRecord, WarmStartResult, check_instance


@dataclass(frozen=True)
class AnalyticWarmStart:
    """An analytic guess of the 6-DoF problem with ``n_nodes`` nodes: ``profile`` is
    ``"straight_line"`` (Szmuk & Acikmese) or ``"cubic_profile"`` (the solver's default), the
    names of :data:`scpformer.problems.pdg6dof.guess.ANALYTIC_GUESSES`."""

    n_nodes: int = 50
    profile: str = "straight_line"

    def __post_init__(self) -> None:
        if self.profile not in ANALYTIC_GUESSES:
            raise ValueError(
                f"profile must be one of {', '.join(ANALYTIC_GUESSES)}, got {self.profile!r}"
            )

    def guess(self, instance: Any) -> WarmStartResult:
        check_instance(instance, PDGInstance, "pdg6dof")
        start = time.perf_counter()
        z = ANALYTIC_GUESSES[self.profile](instance, self.n_nodes)
        record = WarmStartRecord(
            source=self.profile,
            time_s=time.perf_counter() - start,
            cost=-float(z.x[-1, 13]),  # C(z) = -m_N (T-SCvx paper, Eq. 2)
            constraint_to_go=math.nan,
        )
        return WarmStartResult(z, record)
