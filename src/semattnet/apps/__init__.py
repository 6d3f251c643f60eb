"""Experiments built from the library: the demo, the Table 2 ablation, the benchmark harness.
Imported on demand (``semattnet.apps.demo``, ...), not re-exported here."""
