"""Non-learned baselines: the IP-Basic-style classical completion."""

from semattnet.baselines.classical import ClassicalCompleter, complete_classical

__all__ = ["ClassicalCompleter", "complete_classical"]
