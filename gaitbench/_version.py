"""The installed version, read by the package face and by provenance without importing either."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("gaitbench")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"
