"""analysis: making sense of logs.

Owns trace evaluation of specs over logged episodes, per-episode and per-study
tables, statistics, plots, the report, and fitting driver models to logs.
Must not run simulations.
"""
