"""A small cell with a curved belt (guide rails) and a transfer unit, for the drawing tests."""

from pathlib import Path

CURVE_CELL = """
cell: {name: curve_test, step: 0.001, seed: 3}
belts:
  - {name: infeed, start: [0.0, 0.0], end: [1.0, 0.0], width: 0.4, speed: 0.5,
     max_speed: 2.0, acceleration: 1.0, friction: 0.35}
  - name: bend
    curve: {centre: [1.0, 0.6], inner_radius: 0.4, outer_radius: 0.8, start_angle: -90,
            end_angle: 0, direction: ccw, guide_rails: true}
    speed: 0.5
    max_speed: 2.0
    acceleration: 1.0
    friction: 0.35
obstacles:
  - {name: wall_right, kind: wall, points: [[0.0, -0.205], [1.0, -0.205]]}
part_types:
  - {name: disc, shape: disc, radius: 0.015, height: 0.02, mass: 0.03}
sources:
  - {name: feed, part_type: disc, region: [0.05, -0.15, 0.2, 0.15], rate: 4.0}
sinks:
  - {name: exit, region: [1.35, 0.55, 1.85, 0.75]}
light_barriers:
  - {name: lb_in, start: [0.3, -0.2], end: [0.3, 0.2], height: 0.005}
actuators:
  - {name: lift, kind: transfer, base: [0.7, 0.0], axis: [0.0, 1.0], length: 0.3,
     width: 0.2, stroke: 0.01, engage_height: 0.005, max_speed: 0.1, surface_speed: 0.3,
     friction: 0.5}
"""


def write_curve_cell(directory: Path) -> Path:
    """Write :data:`CURVE_CELL` to ``directory/curve.yaml``; return its path."""
    path = Path(directory) / 'curve.yaml'
    path.write_text(CURVE_CELL)
    return path


def curve_run(path: str, cell_text: str, seconds: float = 1.0) -> str:
    """Record a run of ``cell_text`` at 100 Hz: three parts riding the centre line of its
    last belt from start to end, every belt at its speed, every actuator rising linearly from
    its lowest to its highest position (a transfer unit passes its engage height)."""
    import numpy as np

    from conveyor_twin.cell import load_cell_text
    from conveyor_twin.record import series as series_mod
    from conveyor_twin.record.writer import McapRecorder
    from conveyor_twin.wire import cdr

    cell = load_cell_text(cell_text)
    belt = cell.belts[-1]
    steps = int(round(seconds * 100))
    line = np.array(belt.centre_line(steps + 3))
    belts = tuple(b.name for b in cell.belts)
    speeds = np.array([b.speed for b in cell.belts])
    acts = tuple(a.name for a in cell.actuators)
    low = np.array([a.position_range[0] for a in cell.actuators])
    high = np.array([a.position_range[1] for a in cell.actuators])
    with McapRecorder(path, cell_yaml=cell_text, seed=1, step_ns=1_000_000) as rec:
        rec.add_topic('/parts', series_mod.PARTS)
        rec.add_topic('/belt_states', series_mod.BELTS)
        rec.add_topic('/actuator_states', series_mod.ACTUATORS)
        for k in range(steps):
            t = k * 10_000_000
            ids = np.arange(1, 4, dtype=np.uint32)
            x, y = line[k:k + 3, 0].copy(), line[k:k + 3, 1].copy()
            rec.record('/parts', t, cdr.encode_part_states(
                t, 'cell', 10 * k, ids, np.zeros(3, np.uint16), x, y, np.zeros(3),
                np.zeros(3), np.zeros(3), np.zeros(3)))
            rec.record('/belt_states', t, cdr.encode_belt_states(t, 'cell', belts, speeds,
                                                                 speeds))
            position = low + (high - low) * k / max(steps - 1, 1)
            rec.record('/actuator_states', t, cdr.encode_actuator_states(
                t, 'cell', acts, position, position))
    return path
