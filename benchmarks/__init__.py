"""Benchmark scripts. Each writes a Markdown report (and charts) into benchmarks/results/."""
