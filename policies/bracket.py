"""What every result with certified ends [lower, upper] shares: its gap, and a dict with the gap."""

from __future__ import annotations

from dataclasses import asdict


class Bracket:
    """Mixin for frozen dataclasses with float fields `lower` and `upper`."""

    lower: float
    upper: float

    @property
    def gap(self) -> float:
        return self.upper - self.lower

    def to_dict(self) -> dict:
        out = asdict(self)
        out["gap"] = self.gap
        return out
