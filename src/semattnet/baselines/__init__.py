"""Non-learned baselines: the IP-Basic-style classical completion."""

from semattnet.baselines.classical import (
    ClassicalCompleter,
    classical_fill_step,
    classical_uncertainty,
    complete_classical,
)

__all__ = ["ClassicalCompleter", "classical_fill_step", "classical_uncertainty", "complete_classical"]
