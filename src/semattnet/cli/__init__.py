"""The ``semattnet`` command line: one module per command group; commands parse options and call the library."""

from semattnet.cli import apps, data, evaluate, models, predict, project, segment, train  # noqa: F401  (register)
from semattnet.cli._group import main

__all__ = ["main"]

if __name__ == "__main__":
    main()
