"""A stalled actuator as a controller sees it: ``actuator_states`` and the diagnostics, in
both layouts (the split layout's micro process reports the loads to the coordinator)."""

from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray
import pytest
from rclpy.node import Node

from conveyor_twin.ros.qos import SLOW_QOS
from conveyor_twin.wire import cdr

pytestmark = pytest.mark.ros
LIMIT = 20.0

CELL = """
cell: {name: stall_cell, frame_id: cell, step: 0.001, gravity: 9.81, seed: 1}
belts:
  - {name: main, start: [0.0, 0.0], end: [2.0, 0.0], width: 0.5, speed: 0.0, max_speed: 2.0,
     acceleration: 2.0, friction: 0.35}
obstacles:
  - {name: far, kind: wall, points: [[0.0, -0.2], [2.0, -0.2]], thickness: 0.01}
part_types:
  - {name: disc, shape: disc, radius: 0.01, height: 0.01, mass: 0.01, inertia: 5.0e-7,
     restitution: 0.0, friction_static: 0.3, friction_sliding: 0.2}
actuators:
  # its paddle's front stops 5 mm short of the far wall's face: a part between is caught
  - {name: pusher, kind: pusher, base: [0.5, 0.2], axis: [0.0, -1.0], length: 0.02,
     width: 0.15, stroke: 0.38, max_speed: 0.8, initial_position: 0.0, restitution: 0.0,
     force_limit: %g}
""" % LIMIT


class _Diagnostics(Node):
    def __init__(self, context) -> None:
        super().__init__('stall_diagnostics', context=context)
        self.received = []
        self.create_subscription(DiagnosticArray, 'diagnostics', self.received.append,
                                 SLOW_QOS)


@pytest.mark.parametrize('layout', ['composed', 'split'])
def test_a_stall_is_on_actuator_states_and_in_the_diagnostics(conveyor_twin_factory, tmp_path,
                                                              layout):
    cell_file = Path(tmp_path) / 'stall_cell.yaml'
    cell_file.write_text(CELL)
    twin = conveyor_twin_factory(str(cell_file), layout=layout, chunk=50)
    diagnostics = twin.add_node(_Diagnostics(twin.context))
    twin.spawn('disc', [0.5], [0.0], [0.0])
    twin.set_actuator('pusher', 0.38)
    twin.step_until(lambda: twin.actuator('pusher').stalled, max_steps=1000,
                    what='the pusher stalls at the far wall')
    twin.step(1000 - twin.step_index % 1000)   # up to the next diagnostics
    states = [cdr.decode_actuator_states(m) for m in twin.messages('actuator_states')]
    over = [s for s in states if s.stalled[0] and s.load[0] > LIMIT]
    assert over, 'no actuator_states message with the pusher stalled over its limit'
    assert twin.actuator('pusher').stalled
    assert twin.actuator('pusher').position < 0.375
    twin.wait_until(lambda: any(m.header.stamp.sec >= 1 for m in diagnostics.received),
                    timeout=30.0, what='the diagnostics of the first second')
    status = [s for m in diagnostics.received for s in m.status
              if s.name == 'conveyor_twin: actuators'][-1]
    assert status.level == b'\x01' and 'pusher stalled: load' in status.message
    assert f'over its force_limit {LIMIT:g} N' in status.message
    # commanded back it retracts and the stall clears
    twin.set_actuator('pusher', 0.0)
    twin.step(100)
    assert not twin.actuator('pusher').stalled
    assert twin.actuator('pusher').position < 0.3
