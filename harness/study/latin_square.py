"""Counterbalanced orders of conditions: the balanced Latin square of Williams (1949).

For n conditions (n even) the square has n rows; each condition appears once in each position
(column) and each ordered pair (a, b), a != b, appears exactly once as consecutive conditions, so
first-order carryover is balanced. For n odd no single square does that: the design is the square
and its mirror image (2n rows). Participant p drives the order of row p mod len(rows), so the
design is exactly balanced when the number of participants is a multiple of len(rows) (21
participants over 4 conditions: one row is used 6 times, the others 5, as in any 21-person study).
"""

from __future__ import annotations


def williams_rows(n: int) -> list[tuple[int, ...]]:
    """The rows of a Williams design for conditions 0..n-1 (n rows if n is even, else 2n)."""
    if n < 1:
        raise ValueError(f"a Latin square needs at least one condition, got {n}")
    # First row 0, 1, n-1, 2, n-2, ...: consecutive differences then cover every residue once.
    first = [0]
    low, high = 1, n - 1
    while len(first) < n:
        first.append(low)
        low += 1
        if len(first) < n:
            first.append(high)
            high -= 1
    rows = [tuple((c + shift) % n for c in first) for shift in range(n)]
    if n % 2 == 1 and n > 1:
        rows += [tuple(reversed(row)) for row in rows]
    return rows


def participant_order(participant: int, n: int) -> tuple[int, ...]:
    """The order (condition indices by position) participant `participant` (0-based) drives."""
    rows = williams_rows(n)
    return rows[participant % len(rows)]
