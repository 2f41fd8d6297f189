"""Benchmarks that ship with the package (``spikeview bench``): error against run time of every method."""
