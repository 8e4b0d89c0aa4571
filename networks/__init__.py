"""networks: the town.

Owns the town description (schema, validation), the directed-road states X,
road lengths, shortest paths, and the SUMO network build (netconvert, cached by
content hash). Must not know about trust.
"""

from trustroute.core.errors import InputError
from trustroute.networks.town import DEFAULT_TOWN_PATH, INCIDENT_TYPES, Town, load_town

__all__ = ["DEFAULT_TOWN_PATH", "INCIDENT_TYPES", "InputError", "Town", "load_town"]
