"""The packaged driver model to 3 decimals, every transition row summing to 1 as printed, so that
the exact process of docs/synthesis.md ("Labels at thresholds") is the chain a fixed route makes of
the product POMDP; and a fixed route as the policy tests/policies/synthesis/exact_joint.py values."""

from __future__ import annotations

import numpy as np

from trustroute.participants.driver_model import DriverModel


def rounded(values: np.ndarray) -> np.ndarray:
    """Each row of probabilities to 3 decimals, the remainder on its largest entry: the row sums
    to 1 as the decimals it prints as."""
    rows = np.rint(values.reshape(-1, values.shape[-1]) * 1000).astype(np.int64)
    rows[np.arange(rows.shape[0]), rows.argmax(axis=1)] += 1000 - rows.sum(axis=1)
    return (rows / 1000).reshape(values.shape)


def decimal_model(driver: DriverModel) -> DriverModel:
    """`driver` with its takeover probabilities and trust transitions to 3 decimals (`rounded`)."""
    return DriverModel(trust_levels=driver.trust_levels, incident_types=driver.incident_types,
                       takeover_probability=np.rint(driver.takeover_probability * 1000) / 1000,
                       failure_probability=driver.failure_probability,
                       trust_transition=rounded(driver.trust_transition),
                       initial_belief=driver.initial_belief,
                       trust_free_takeover_probability=dict(driver.trust_free_takeover_probability),
                       source_path="<driver model to 3 decimals>")


class RoutePolicy:
    """The slots of `route` for exact_joint_value (-1 past its last road: the episode ends)."""

    def __init__(self, town, route: list[str]) -> None:
        self.slots = [list(town.successors(a)).index(b) for a, b in zip(route, route[1:], strict=False)]

    def action_slots(self, t: int, x: np.ndarray, joint: np.ndarray, beliefs: np.ndarray) -> np.ndarray:
        return np.full(x.shape, self.slots[t] if t < len(self.slots) else -1)
