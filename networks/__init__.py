"""networks: the town.

Owns the town description (schema, validation), the directed-road states X,
road lengths, shortest paths, and the SUMO network build (netconvert, cached by
content hash). Must not know about trust.
"""

from trustroute.core.errors import InputError
from trustroute.networks.cities import CITY, CSOMOR, city_town_path, csomor_town_path
from trustroute.networks.town import BUILT_TOWNS, DEFAULT_TOWN_PATH, INCIDENT_TYPES, Town, load_town

# The packaged towns `city` and `csomor` (docs/cities.md), imported on first use: registered here,
# where both modules are known, since networks/cities.py imports the town module through the importer.
BUILT_TOWNS[CITY] = city_town_path
BUILT_TOWNS[CSOMOR] = csomor_town_path

__all__ = ["DEFAULT_TOWN_PATH", "INCIDENT_TYPES", "InputError", "Town", "load_town"]
