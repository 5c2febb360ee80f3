"""The warm-start interface, now :mod:`scpformer.scp.warmstart` (kept for old imports)."""

from scpformer.scp.warmstart import (  # noqa: F401
    GivenWarmStart,
    PrecomputedWarmStart,
    WarmStart,
    WarmStartRecord,
    WarmStartResult,
    as_provider,
    check_instance,
    guess_each,
    is_provider,
    timed,
    trajectory_cost,
)
