"""The `gaitbench` command line (entry point :func:`gaitbench.cli.main.main`)."""
