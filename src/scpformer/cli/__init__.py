"""scpformer.cli."""
