"""harness/simulation."""
