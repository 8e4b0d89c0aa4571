"""Fitting to a study's logs: one driver model (driver_model.py), a mixture of driver types
(mixture.py), and the posterior-predictive check of fitted models (posterior_check.py)."""
