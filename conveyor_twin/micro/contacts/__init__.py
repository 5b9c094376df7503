"""Contacts of the micro simulator, in three phases run once per substep.

1. :mod:`.broad_phase`: which parts may touch (uniform grid, neighbour list with a skin);
2. :mod:`.narrow_phase`: the contact records of the bodies that touch (normal, points, depth,
   materials), in a canonical order whatever the broad phase;
3. the response, what the contacts do to the bodies, reading only the records (overview and
   the shared friction law in :mod:`.response`): :mod:`.impulses` (impulses and position
   correction) with :mod:`.restitution` (the sweep order and the restitution pass) and
   :mod:`.energy` (the energy limit), or :mod:`.penalty` (penalty forces).

:mod:`.tables` holds the column layouts of the arrays the phases share (model parameters,
activities, static shapes, actuators, contact records). The names below are re-exported so
that ``from conveyor_twin.micro.contacts import ...`` names any of them.
"""

from conveyor_twin.micro.contacts.broad_phase import (  # noqa: F401
    build_grid, grid_table, NB_BUILDS, NB_HEADER, NB_MOVE, NB_N, NB_PAIRS, NB_VALID,
    neighbour_arrays, update_pairs)
from conveyor_twin.micro.contacts.energy import limit_energy  # noqa: F401
from conveyor_twin.micro.contacts.impulses import (  # noqa: F401
    correct_positions, impulse_response, prepare_contacts, RESTITUTION_THRESHOLD, solve_impulses)
from conveyor_twin.micro.contacts.narrow_phase import detect, part_shape, scratch  # noqa: F401
from conveyor_twin.micro.contacts.penalty import penalty_force, penalty_forces  # noqa: F401
from conveyor_twin.micro.contacts.restitution import restitute  # noqa: F401
from conveyor_twin.micro.contacts.response import (  # noqa: F401
    friction_coefficient, MODE_IMPULSE, MODE_PENALTY)
from conveyor_twin.micro.contacts.tables import *  # noqa: F401,F403
