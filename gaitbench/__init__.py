"""gaitbench: benchmark energy-optimal walking of planar biped robots, with every method a plugin.

Importing the package stays cheap (no CasADi, no plugins) so the CLI and plugin listings start fast.
"""

import pluggy

from gaitbench._version import __version__
from gaitbench.registration import Registration

hookimpl = pluggy.HookimplMarker("gaitbench")
"""Marks a plugin function as the implementation of a hook in :mod:`gaitbench.hookspecs`."""



def load_results(path):
    """The cases of a results store as a pandas DataFrame, one row per case (see :mod:`gaitbench.run.store`)."""
    from gaitbench.run.store import load_results as load

    return load(path)


__all__ = ["Registration", "__version__", "hookimpl", "load_results"]
