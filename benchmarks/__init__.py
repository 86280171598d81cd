"""Benchmarks: one module per section, measurement and presentation together (never asserts)."""
