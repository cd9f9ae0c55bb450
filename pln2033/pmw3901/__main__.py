"""``python -m pln2033.pmw3901``: the optical-flow scale table docs/sensors.md quotes."""

from .flow_scale import scale_table

print(scale_table())
