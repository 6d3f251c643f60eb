"""``python -m semattnet``: the command line."""

from semattnet.cli import main

main()
