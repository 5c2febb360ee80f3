"""Experiments: the papers' tables and figures, computed from solved instances and models."""
