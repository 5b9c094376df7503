"""Small synthetic recordings with plausible physics, for the replay, info and plot tests."""

from typing import Dict, List, Tuple

import numpy as np

from conveyor_twin.record.writer import McapRecorder
from conveyor_twin.wire import cdr

DT_NS = 1_000_000
CELL_YAML = 'cell:\n  name: synthetic_rig\n  frame_id: cell\n  step: 0.001\n'
BELT_TOPIC = '/belt_states'
CLOCK_TOPIC = '/clock'
BELTS = ('infeed', 'main')


def belt_clock(path: str, seconds: float, *, clock: bool = True, compression: str = 'lz4',
               chunk_ns: int = 100 * DT_NS) -> List[Tuple[str, int, bytes]]:
    """Record belt_states (+ /clock) at 1 kHz for ``seconds``; return (topic, t, data) sent.

    A chunk is closed every ``chunk_ns`` of simulation time [ns].
    """
    steps = int(round(seconds * 1000))
    sent = []
    with McapRecorder(path, compression=compression, cell_yaml=CELL_YAML, seed=1,
                      step_ns=DT_NS, flush_sim_period_ns=chunk_ns) as rec:
        rec.add_topic(BELT_TOPIC, 'conveyor_twin_msgs/msg/BeltStates')
        if clock:
            rec.add_topic(CLOCK_TOPIC, 'rosgraph_msgs/msg/Clock')
        for step in range(steps):
            t = step * DT_NS
            speed = np.array([0.5, 0.5 + 1e-4 * step])
            items = [(BELT_TOPIC, cdr.encode_belt_states(t, 'cell', BELTS, speed, speed))]
            if clock:
                items.insert(0, (CLOCK_TOPIC, cdr.encode_clock(t)))
            for topic, data in items:
                assert rec.record(topic, t, data)
                sent.append((topic, t, data))
    return sent


def conveyor_run(path: str, seconds: float = 4.0, parts: int = 12) -> Dict[str, int]:
    """Record a plausible run: parts on a belt deflected sideways, a light barrier, belts, density.

    Parts enter at x = 0 every 0.25 s and ride at the belt speed; past x = 1 m a deflector pushes
    them to y = 0.15 m. A light barrier at x = 0.8 m is blocked while a part (10 mm radius) is
    in its beam. The main belt is commanded from 0.5 to 0.3 m/s at t = 2 s and ramps at
    0.5 m/s^2. A density blob travels along the 3 m x 0.4 m grid. Parts at 100 Hz, density at
    10 Hz, everything else at 1 kHz.

    :return: message count per topic.
    """
    steps = int(round(seconds * 1000))
    counts: Dict[str, int] = {}
    entry = np.arange(parts) * 0.25
    x_lb, radius = 0.8, 0.01
    blocked_prev = False
    nx, ny, res = 60, 8, 0.05
    gx = (np.arange(nx) + 0.5) * res
    gy = (np.arange(ny) + 0.5) * res - 0.2
    x = np.zeros(parts)
    speed = 0.5
    with McapRecorder(path, cell_yaml=CELL_YAML, seed=3, step_ns=DT_NS) as rec:
        for topic, type_name in (('/parts', 'PartStates'), ('/density', 'DensityGrid'),
                                 ('/light_barriers', 'LightBarrierStates'),
                                 ('/light_barrier_edges', 'LightBarrierEdge'),
                                 ('/belt_states', 'BeltStates')):
            rec.add_topic(topic, 'conveyor_twin_msgs/msg/' + type_name)
        rec.add_topic('/clock', 'rosgraph_msgs/msg/Clock')

        def put(topic: str, t: int, data: bytes) -> None:
            rec.record(topic, t, data)
            counts[topic] = counts.get(topic, 0) + 1

        for step in range(steps):
            t_s = step * 1e-3
            t = step * DT_NS
            target = 0.5 if t_s < 2.0 else 0.3
            speed = max(target, speed - 0.5e-3) if speed > target else speed
            on = entry <= t_s
            x = np.where(on, x + speed * 1e-3, 0.0)
            y = np.clip((x - 1.0) * 0.5, 0.0, 0.15)
            put('/clock', t, cdr.encode_clock(t))
            put('/belt_states', t, cdr.encode_belt_states(
                t, 'cell', BELTS, np.array([0.5, target]), np.array([0.5, speed])))
            blocked = bool(np.any(on & (np.abs(x - x_lb) < radius)))
            if blocked != blocked_prev:
                put('/light_barrier_edges', t, cdr.encode_light_barrier_edge(
                    t - 400_000, 'cell', 'lb_mid', blocked, 1))
                blocked_prev = blocked
            put('/light_barriers', t, cdr.encode_light_barrier_states(
                t, 'cell', step, ('lb_mid',), np.array([blocked]), np.array([0], np.uint32)))
            if step % 10 == 0:
                ids = np.flatnonzero(on).astype(np.uint32) + 1
                n = len(ids)
                put('/parts', t, cdr.encode_part_states(
                    t, 'cell', step, ids, np.zeros(n, np.uint16), x[on], y[on], np.zeros(n),
                    np.full(n, speed), np.zeros(n), np.zeros(n)))
            if step % 100 == 0:
                cx = 0.2 + speed * t_s
                blob = np.exp(-((gx[None, :] - cx) ** 2 / 0.02 + gy[:, None] ** 2 / 0.01))
                density = (400.0 * blob).astype(np.float32)
                put('/density', t, cdr.encode_density_grid(
                    t, 'cell', step, 'buffer', 0.0, -0.2, res, nx, ny, density,
                    float(density.sum() * res * res)))
    return counts
