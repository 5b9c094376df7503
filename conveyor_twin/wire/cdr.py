"""The CDR codec of the contract messages in one namespace: ``from conveyor_twin.wire import cdr``.

Its parts: :mod:`.builder` (the format, the encapsulation, times, :class:`CdrError`, the
writers), :mod:`.reader` (the bounds-checked reader), :mod:`.encoders` (every message straight
from numpy; the hot streams with reusable buffers), :mod:`.decoders` (every message back into
numpy arrays and named tuples), :mod:`.fault_state` and :mod:`.diagnostics` (the ``faults`` and
``diagnostics`` messages and their types). Times are integer nanoseconds of simulation time.
"""

from conveyor_twin.wire.builder import (CdrError, ENCAPSULATION_LE, NS_PER_S, stamp_of,
                                        stamp_parts)
from conveyor_twin.wire.decoders import (ActuatorStatesData, decode_actuator_command,
                                         decode_actuator_states,
                                         decode_belt_command, decode_belt_states, decode_clock,
                                         decode_command_origin, decode_density_grid,
                                         decode_diagnostic_array, decode_fault_state,
                                         decode_light_barrier_edge,
                                         decode_light_barrier_states, decode_part_states,
                                         decode_reset_request, decode_spawn_request,
                                         DensityGridData, density_zone, EdgeData, NamedPairData,
                                         PartStatesData)
from conveyor_twin.wire.encoders import (ActuatorStatesEncoder, BeltStatesEncoder,
                                         DensityGridEncoder, encode_actuator_command,
                                         encode_actuator_states, encode_belt_command,
                                         encode_belt_states, encode_clock,
                                         encode_density_grid, encode_light_barrier_edge,
                                         encode_light_barrier_states, encode_part_states,
                                         encode_reset_request, encode_spawn_request,
                                         LightBarrierStatesEncoder, PartStatesEncoder)

__all__ = [
    'ActuatorStatesData', 'ActuatorStatesEncoder', 'BeltStatesEncoder', 'CdrError', 'decode_actuator_command',
    'decode_actuator_states', 'decode_belt_command', 'decode_belt_states', 'decode_clock',
    'decode_command_origin', 'decode_density_grid', 'decode_diagnostic_array',
    'decode_fault_state', 'decode_light_barrier_edge', 'decode_light_barrier_states',
    'decode_part_states', 'decode_reset_request', 'decode_spawn_request', 'DensityGridData',
    'DensityGridEncoder', 'density_zone', 'EdgeData', 'encode_actuator_command',
    'encode_actuator_states', 'encode_belt_command', 'encode_belt_states', 'encode_clock',
    'encode_density_grid', 'encode_light_barrier_edge', 'encode_light_barrier_states',
    'encode_part_states', 'encode_reset_request', 'encode_spawn_request', 'ENCAPSULATION_LE',
    'LightBarrierStatesEncoder', 'NamedPairData', 'NS_PER_S', 'PartStatesData',
    'PartStatesEncoder', 'stamp_of', 'stamp_parts',
]
