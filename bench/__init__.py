"""Benchmarks of creep_online, run from the repository root as ``python -m bench.NAME``.

Shared statistics, the JSON report writer and the results path rule live in :mod:`bench.harness`.
Not part of the installed package.
"""
