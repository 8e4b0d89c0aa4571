"""participants: the human in the loop.

Owns the driver model file (trust dynamics, takeover model, report model), its
validation, the synthetic driver and populations with individual variation.
Must not know about SUMO.
"""

from participants.driver_model import DEFAULT_DRIVER_MODEL_PATH, DriverModel, load_driver_model

__all__ = ["DEFAULT_DRIVER_MODEL_PATH", "DriverModel", "load_driver_model"]
