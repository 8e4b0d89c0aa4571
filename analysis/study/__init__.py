"""The analysis of a study directory: per spec and condition, paired effects, order effects, per
driver type and beside the paper (analysis.py and the table modules), the display tables
(display.py), plots (plots.py) and the report (report.py)."""
