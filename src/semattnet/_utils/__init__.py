"""Private helpers shared by every subpackage: atomic writes, device / number-format rules, process groups."""
