"""analysis: making sense of logs.

Owns trace evaluation of specs over logged episodes (satisfaction.py), statistics
(statistics.py), reading a study directory (study_directory.py), the paper's figures
(paper_figures.py) and display formatting (formatting.py), and by topic:
study/ (the tables, plots and report of a study), fitting/ (driver models and driver
types fitted to logs, their posterior-predictive check) and carla_study/ (importing and
analysing the real CARLA study's logs). Must not run simulations.
"""
