"""Closed-loop tracking of a solved walk: reference trajectories, controllers and observers driven through the
hybrid simulator, and the tracking-error results."""
