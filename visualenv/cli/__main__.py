"""`python -m visualenv.cli`: the `visualenv` command."""

from visualenv.cli import main

main()
