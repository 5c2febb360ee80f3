"""scpformer.dynamics."""
