"""The robot and its world: parameters, terrain, experiments, the derived equations of motion, energetics and the
hybrid simulator that re-simulates every solution. Imports nothing above it."""
