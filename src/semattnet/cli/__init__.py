"""The ``semattnet`` command line: one module per command group; commands parse options and call the library."""

from semattnet.cli import (  # noqa: F401  (register the commands)
    adapt,
    apps,
    bag,
    data,
    evaluate,
    generalist,
    models,
    predict,
    project,
    ros,
    segment,
    train,
    weights,
)
from semattnet.cli._group import main

__all__ = ["main"]

if __name__ == "__main__":
    main()
