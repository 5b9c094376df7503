"""Synthetic runs recorded through McapRecorder, with the expected content kept for checks."""

import numpy as np

from conveyor_twin.record.writer import McapRecorder
from conveyor_twin.wire import cdr

DT_NS = 1_000_000
CELL_YAML = 'cell:\n  name: test_rig\n  frame_id: cell\n  step: 0.001\n'
BELTS = ('infeed', 'main')
ACTUATORS = ('pusher',)
BARRIERS = ('lb_in', 'lb_out')

TOPICS = {
    '/parts': 'conveyor_twin_msgs/msg/PartStates',
    '/density': 'conveyor_twin_msgs/msg/DensityGrid',
    '/light_barriers': 'conveyor_twin_msgs/msg/LightBarrierStates',
    '/light_barrier_edges': 'conveyor_twin_msgs/msg/LightBarrierEdge',
    '/belt_states': 'conveyor_twin_msgs/msg/BeltStates',
    '/actuator_states': 'conveyor_twin_msgs/msg/ActuatorStates',
    '/clock': 'rosgraph_msgs/msg/Clock',
}


def step_messages(step, rng):
    """Return {topic: (cdr bytes, expected fields)} of one synthetic step."""
    t = step * DT_NS
    n = step % 7
    parts = (np.arange(1, n + 1, dtype=np.uint32) + step, (np.arange(n) % 3).astype(np.uint16),
             *[rng.normal(size=n) for _ in range(6)])
    density = rng.random((2, 3)).astype(np.float32)
    blocked = np.array([step % 2 == 0, step % 3 == 0])
    counts = np.array([step, 2 * step], dtype=np.uint32)
    speeds = (np.array([0.5, 1.0]), np.array([0.25 + step * 1e-3, 1.0]))
    positions = (np.array([0.1]), np.array([0.05]))
    out = {
        '/parts': (cdr.encode_part_states(t, 'cell', step, *parts), parts),
        '/density': (cdr.encode_density_grid(t, 'cell', step, 'buffer', 1.0, -0.2, 0.05, 3, 2,
                                             density, float(density.sum())), density),
        '/light_barriers': (cdr.encode_light_barrier_states(t, 'cell', step, BARRIERS, blocked,
                                                            counts), (blocked, counts)),
        '/belt_states': (cdr.encode_belt_states(t, 'cell', BELTS, *speeds), speeds),
        '/actuator_states': (cdr.encode_actuator_states(t, 'cell', ACTUATORS, *positions),
                             positions),
        '/clock': (cdr.encode_clock(t), t),
    }
    if step % 5 == 0 and step > 0:
        out['/light_barrier_edges'] = (
            cdr.encode_light_barrier_edge(t - 300, 'cell', 'lb_in', step % 10 == 0, step),
            step)
    return out


def record_run(path, steps=60, *, seed=7, **options):
    """Record ``steps`` synthetic steps (plus two accepted commands); return (stats, sent).

    ``sent`` maps topic -> list of (log_time, cdr bytes, expected) in the order recorded.
    """
    rng = np.random.default_rng(seed)
    sent = {topic: [] for topic in TOPICS}
    sent['/conveyor_twin/accepted/belt_command'] = []
    sent['/conveyor_twin/accepted/actuator_command'] = []
    with McapRecorder(path, cell_yaml=CELL_YAML, seed=seed, step_ns=DT_NS, **options) as rec:
        for topic, type_name in TOPICS.items():
            rec.add_topic(topic, type_name)
        for step in range(steps):
            for topic, (data, expected) in step_messages(step, rng).items():
                t = step * DT_NS
                if rec.record(topic, t, data):
                    sent[topic].append((t, data, expected))
            if step in (10, 30):
                data = cdr.encode_belt_command('main', 0.1 * step)
                rec.record_accepted_command('belt', (step + 1) * DT_NS, data)
                sent['/conveyor_twin/accepted/belt_command'].append(
                    ((step + 1) * DT_NS, data, ('main', 0.1 * step)))
            if step == 20:
                data = cdr.encode_actuator_command('pusher', 0.08)
                rec.record_accepted_command('actuator', (step + 1) * DT_NS, data)
                sent['/conveyor_twin/accepted/actuator_command'].append(
                    ((step + 1) * DT_NS, data, ('pusher', 0.08)))
    return rec.stats, sent
