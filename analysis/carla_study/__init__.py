"""The real CARLA study of the paper: the authors' Town01 tables (town01.py), importing their logs
(log_import.py, with the imported tables' schemas in log_schema.py), and the analysis of the
imported study (analysis.py). The packaged data live in analysis/data/real_study/."""
