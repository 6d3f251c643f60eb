"""``python -m semattnet.cli``."""

from semattnet.cli import main

main()
