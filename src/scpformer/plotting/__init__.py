"""scpformer.plotting."""
