"""simbridge benchmarks: each module measures a hot path side by side with a baseline.

Run them all with ``python -m bench`` (or ``make bench``), one with ``python -m bench NAME``.
The machine is shared and noisy: compare the ratios printed, not absolute times across runs.
"""
