"""The node's services, name -> type: one table for the node, the harness's client
and the monitor's bridge (the names are relative to the node, ``/mm_beagle/NAME``)."""

from __future__ import annotations

NAMES = ("get_sensor_data", "get_sensor_settings", "set_resolution", "get_samples")


def service_types() -> dict[str, type]:
    """{name: mm_interfaces service type}; imported on call (needs the built interfaces)."""
    from mm_interfaces.srv import GetSamples, GetSensorData, GetSensorSettings, SetResolution

    types = (GetSensorData, GetSensorSettings, SetResolution, GetSamples)
    return dict(zip(NAMES, types, strict=True))
