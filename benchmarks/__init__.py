"""Benchmarks run by `make bench`: every `bench_*.py` module here exposes `run()`.

`run()` returns a list of result dicts, each with a `name`. A row with one headline figure gives it
as `value` with its `unit`, and, where the benchmark compares against a baseline measured in the
same run, `baseline` and `ratio` (value / baseline). A row of several figures (a peer table's
sides, a time limit's runs, a live study's latencies) names each figure's unit in its key
(`seconds`, `median_ms`, `peak_rss_mb`, `bytes_per_s`; `lower` and `upper` are probabilities) and
its ratios by what they divide (`ratio_to_limit`, `time_ratio_ours_over_storm`). The machine is
shared, so most timings carry the 1-minute load average beside them (`load_average_1min`,
`load_average` or `load`); a few absolute figures do not (bench_net's first build, bench_parts'
read and verify, bench_foundation's driver steps, bench_episode's 200 episodes, bench_live's frame
rate and memory). Extra keys are allowed (e.g. `target`, `note`).
"""
