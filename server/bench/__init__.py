"""Benchmarks (`robocal bench`) and the simulated suites they run: not used by the product."""
