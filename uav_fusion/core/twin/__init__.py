"""The digital twin: a physically modelled flight written in the real Dataset-28 formats."""

from uav_fusion.core.twin.config import TwinConfig, load_twin_config
from uav_fusion.core.twin.generate import TwinFlight, generate_twin, twin_to_flight
from uav_fusion.core.twin.trajectory import FlightPlan, load_flight_plan
from uav_fusion.core.twin.writers import write_twin

__all__ = [
    "FlightPlan",
    "TwinConfig",
    "TwinFlight",
    "generate_twin",
    "load_flight_plan",
    "load_twin_config",
    "twin_to_flight",
    "write_twin",
]
