"""scpformer.scp."""
