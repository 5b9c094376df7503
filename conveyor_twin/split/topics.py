"""Hidden topics of the split layout's per-step coupling between the twin's own processes.

Their payloads (``std_msgs/UInt8MultiArray`` CDR built by hand) are the protocol's:
:mod:`conveyor_twin.split.protocol`. Topic names start with ``_`` so ``ros2 topic list`` hides
them.

The coordinator sends every payload on :data:`COUPLING_TOPIC` and the scale nodes answer on
:data:`DONE_TOPIC`. Cells with ``macro``/``auto`` zones also couple the two scale nodes every
step (:mod:`conveyor_twin.split.mirror`): the micro node sends its state after its step on
:data:`MICRO_STATE_TOPIC`, the macro node answers with the hand-over's edits on
:data:`EDITS_TOPIC`.
"""

from conveyor_twin.coord.layout import Role

COUPLING_TOPIC = '_coupling/to_scales'
DONE_TOPIC = '_coupling/from_scales'
MICRO_STATE_TOPIC = '_coupling/micro_state'
EDITS_TOPIC = '_coupling/edits'

#: The hand-over exchange of each scale role: (the topic it sends on, the topic it takes).
EXCHANGE_TOPICS = {Role.MICRO: (MICRO_STATE_TOPIC, EDITS_TOPIC),
                   Role.MACRO: (EDITS_TOPIC, MICRO_STATE_TOPIC)}
