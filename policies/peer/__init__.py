"""Independent solvers run beside ours: the product POMDP as a PRISM model, and Storm on it.

Owns the export of specs whose atoms are all state predicates over X × Θ (roads and hidden
trust) and the call into Storm's belief exploration (stormpy, the optional `[peer]` extra).
Must not be imported by the solvers it checks.
"""
