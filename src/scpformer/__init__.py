"""scpformer: sequential convex programming for spacecraft, with learned warm starts."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("scpformer")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"
