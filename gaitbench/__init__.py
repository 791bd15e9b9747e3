"""gaitbench: benchmark energy-optimal walking of planar biped robots, with every method a plugin.

Importing the package stays cheap (no CasADi, no plugins) so the CLI and plugin listings start fast.
"""

from importlib.metadata import PackageNotFoundError, version

import pluggy

from gaitbench.registration import Registration

try:
    __version__ = version("gaitbench")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

hookimpl = pluggy.HookimplMarker("gaitbench")
"""Marks a plugin function as the implementation of a hook in :mod:`gaitbench.hookspecs`."""

__all__ = ["Registration", "__version__", "hookimpl"]
