"""How a twin's processes are laid out, and the role of each process (no ROS imports).

:class:`Layout` says where the stages run: ``composed`` (one process steps everything) or
``split`` (three processes, coupled over hidden topics: :mod:`conveyor_twin.split`).
:class:`Role` names the three processes of the split layout; the scale roles' values are
the role bytes of the split layout's ``done`` replies (:mod:`conveyor_twin.split.protocol`).
"""

from enum import Enum, IntEnum


class Layout(str, Enum):
    """Where a twin's stages run; members equal their strings (``Layout.SPLIT == 'split'``)."""

    COMPOSED = 'composed'
    SPLIT = 'split'


class Role(IntEnum):
    """One process of the split layout; the value is its role byte on the wire."""

    COORDINATOR = 0
    MICRO = 1
    MACRO = 2

    @property
    def node_name(self) -> str:
        """The ROS node this role's process runs."""
        return _NODE_NAMES[self]


_NODE_NAMES = {Role.COORDINATOR: 'scale_coordinator', Role.MICRO: 'micro_simulator',
               Role.MACRO: 'macro_simulator'}
#: The roles that step a scale (they answer every step of the coordinator).
SCALE_ROLES = (Role.MICRO, Role.MACRO)
