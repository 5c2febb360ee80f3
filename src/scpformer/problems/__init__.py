"""scpformer.problems."""
