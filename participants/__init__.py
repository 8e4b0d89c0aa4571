"""participants: the human in the loop.

Owns the driver model file (trust dynamics, takeover model, report model), its
validation, the synthetic driver, populations with individual variation and driver-population
files (mixtures of driver types).
Must not know about SUMO.
"""

from trustroute.participants.driver_model import (
    DEFAULT_DRIVER_MODEL_PATH,
    DriverModel,
    check_covers_town,
    driver_model_from_dict,
    load_driver_model,
)
from trustroute.participants.driver_population import (
    DriverPopulation,
    DriverType,
    driver_population_from_dict,
    load_driver_population,
    single_type_population,
    write_driver_population,
)
from trustroute.participants.population import (
    PopulationConfig,
    population_config_from_dict,
    sample_population,
)
from trustroute.participants.synthetic_driver import SyntheticDriver

__all__ = [
    "DEFAULT_DRIVER_MODEL_PATH",
    "DriverModel",
    "DriverPopulation",
    "DriverType",
    "PopulationConfig",
    "SyntheticDriver",
    "check_covers_town",
    "driver_model_from_dict",
    "driver_population_from_dict",
    "load_driver_model",
    "load_driver_population",
    "population_config_from_dict",
    "sample_population",
    "single_type_population",
    "write_driver_population",
]
