"""Example gaitbench plugins, installed as a package: a solver, an objective and a reporter.

Each module registers one kind through a ``gaitbench`` entry point (``pyproject.toml``). Importing a module must stay
cheap, since ``gaitbench plugins`` imports them all to list them: heavy imports go inside the factories and methods.
"""
