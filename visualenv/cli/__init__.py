"""The `visualenv` command: validate, build, inspect, init, preview, schema, train, play, eval, view, export-policy, bench, info,
compile-kernels, bench-rllib; each group of commands in a module of its own.

Bad input never shows a traceback: spec problems print as
``file:line:column: field: message`` lines and exit with status 2.
"""

from visualenv.cli import agents, authoring, machine, training  # noqa: F401 - each registers its commands on the group
from visualenv.cli.group import main

__all__ = ["main"]
