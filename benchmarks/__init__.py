"""Benchmarks run by `make bench`: every `bench_*.py` module here exposes `run()`.

`run()` returns a list of result dicts with `name`, `value`, `unit`, and, where the
benchmark compares against a baseline measured in the same run, `baseline` and
`ratio` (value / baseline). Extra keys are allowed (e.g. `target`, `note`).
"""
