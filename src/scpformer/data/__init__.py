"""Datasets of solved problems: generation, storage, augmentation, splits and loading.

=================  =========================================================================
module             role
=================  =========================================================================
family             the :class:`DatasetFamily` protocol a problem family implements; registry
pdg6dof_family     the 6-DoF powered descent family (T-SCvx)
rendezvous_family  the ISS rendezvous family (ART): convex and SCP twins of each instance
executors          local process pool and Ray actors; per-instance seeds and time limits
generate           sharded, resumable generation (:func:`generate.generate`)
storage            HDF5 shards, manifest, checksums, verification, lazy random access
augment            the T-SCvx rotation augmentation as a checked dataset transform
splits             splits grouped by base instance; training-set normalization statistics
torch_views        PyTorch ``Dataset`` views for T-SCvx and ART (imports torch; not here)
=================  =========================================================================
"""

from scpformer.data.errors import DatasetError
from scpformer.data.family import (
    DatasetFamily,
    FamilySpec,
    Field,
    SampleResult,
    build_family,
    family_names,
    get_family_spec,
    register_family,
)

__all__ = [
    "DatasetError",
    "DatasetFamily",
    "FamilySpec",
    "Field",
    "SampleResult",
    "build_family",
    "family_names",
    "get_family_spec",
    "register_family",
]
