"""What every result with certified ends [lower, upper] shares: its gap, and a dict with the gap."""

from __future__ import annotations

from dataclasses import Field, asdict
from typing import Any, ClassVar


class Bracket:
    """Mixin for frozen dataclasses with float fields `lower` and `upper`."""

    lower: float
    upper: float
    __dataclass_fields__: ClassVar[dict[str, Field[Any]]]   # set on each dataclass that mixes it in

    @property
    def gap(self) -> float:
        return self.upper - self.lower

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["gap"] = self.gap
        return out
