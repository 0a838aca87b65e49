"""One-off experiments: scripts that answered one question once (see experiments/README.md). Run them from the
repository root as modules, e.g. ``python -m experiments.diagnose_grouping --help``; they import the project's
packages like any other code (no sys.path edits)."""
