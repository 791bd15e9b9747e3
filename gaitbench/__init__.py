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



def load_results(path):
    """The cases of a results store as a pandas DataFrame, one row per case (see :mod:`gaitbench.store`)."""
    from gaitbench.store import load_results as load

    return load(path)


__all__ = ["Registration", "__version__", "hookimpl", "load_results"]
