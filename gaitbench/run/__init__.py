"""Suites into cases into stored results: the suite file and its schema, cases, the runner and its executors, the
results store, provenance and the memory estimate."""
