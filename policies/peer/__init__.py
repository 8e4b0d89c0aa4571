"""Independent solvers run beside ours: the product POMDP as Storm's DRN, Storm and PAYNT on it.

Owns the export of specs whose atoms are all state predicates over X × Θ (roads and hidden
trust), the call into Storm's belief exploration (stormpy) and into PAYNT's finite-state
controller synthesis (paynt), both from the optional `[peer]` extra. Must not be imported by the
solvers it checks.
"""
