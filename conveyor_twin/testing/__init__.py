"""Test a controller against the twin without ``ros2 launch``: the public testing API.

A test starts a :class:`LockstepTwin` (or takes the ``conveyor_twin`` pytest fixture), attaches
its controller (a node of the same process or a process of its own), steps the twin and reads
what a controller reads::

    from conveyor_twin.testing import LockstepTwin

    with LockstepTwin(seed=3) as twin:
        twin.add_node(MyController(context=twin.context))
        twin.step_until(lambda: twin.belt('main').commanded_speed == 0.0, max_steps=2000,
                        what='the controller stops the belt')

Every twin runs in lockstep in a ROS domain of its own on loopback, so tests of one run, or of
parallel runs (``pytest -n 2``), never see each other's traffic. See ``docs/testing.md``.
"""

from conveyor_twin.testing.cells import quiet_cell
from conveyor_twin.testing.driver import CommandResult, Driver
from conveyor_twin.testing.errors import (CommandRejectedError, ConditionNotMet,
                                          FaultRejectedError, ServiceError, TwinClosedError,
                                          TwinTimeoutError)
from conveyor_twin.testing.harness import (ActuatorState, BarrierState, BeltSample,
                                           BeltState, CommandRecord, DEFAULT_CHUNK,
                                           DensityGrid, Edge, LockstepTwin, PartStates)
from conveyor_twin.testing.pacing import StepAck
from conveyor_twin.testing.probe import Probe
from conveyor_twin.testing.processes import RosProcesses, stop_all_started, stop_process
from conveyor_twin.testing.ros_env import (claim_domain_id, configure_session, DomainLease,
                                           lease_domain_id, ros_subprocess_env, wait_for)
from conveyor_twin.testing.shm import dead_shm_files, remove_dead_shm_files

__all__ = [
    'ActuatorState', 'BarrierState', 'BeltSample', 'BeltState', 'claim_domain_id',
    'CommandRecord', 'CommandRejectedError', 'CommandResult', 'ConditionNotMet',
    'configure_session', 'dead_shm_files', 'DEFAULT_CHUNK', 'DensityGrid', 'DomainLease', 'Driver', 'Edge',
    'FaultRejectedError',
    'lease_domain_id', 'LockstepTwin', 'PartStates', 'Probe', 'quiet_cell',
    'StepAck',
    'remove_dead_shm_files', 'ros_subprocess_env', 'RosProcesses', 'ServiceError',
    'stop_all_started', 'stop_process', 'TwinClosedError', 'TwinTimeoutError', 'wait_for',
]
