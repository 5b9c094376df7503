"""The MarkerArray encoder: the per-build fast path writes the bytes of the general writer."""

import glob
import os

import numpy as np
import pytest

from conveyor_twin.cell import load_cell, load_cell_text
from conveyor_twin.output import markers as m
from conveyor_twin.wire.builder import CdrBuilder, stamp_parts, string_bytes

from ..viz.curve_cell import CURVE_CELL

EXAMPLES = sorted(glob.glob(os.path.join(os.path.dirname(m.__file__), '..', 'cell', 'examples',
                                         '*.yaml')))


def random_marker(rng, n_points):
    return m._Marker(f'ns/{int(rng.integers(0, 100))}', int(rng.integers(0, 5)),
                     int(rng.integers(1, 8)), pose=tuple(rng.normal(size=4)),
                     scale=tuple(rng.uniform(0, 1, 3)), colour=tuple(rng.uniform(0, 1, 4)),
                     points=rng.normal(size=(n_points, 3)) if n_points else None)


@pytest.mark.parametrize('offset', range(8))
@pytest.mark.parametrize('n_points', [0, 1, 2, 1000])
def test_fast_marker_equals_general_writer_at_every_alignment(offset, n_points):
    rng = np.random.default_rng(offset * 10 + n_points)
    marker = random_marker(rng, n_points)
    stamp_ns = 1_234_567_891_011
    general = CdrBuilder()
    general.buf.extend(bytes(offset))
    m._write_marker(general, marker, stamp_ns, 'cell')
    fast = bytearray(offset)
    m._append_marker(fast, marker, m._STAMP.pack(*stamp_parts(stamp_ns)),
                     string_bytes('cell'))
    assert bytes(fast) == bytes(general.buf)


@pytest.mark.parametrize('cell_file', [None] + EXAMPLES + ['curve'])
def test_cell_markers_equal_the_general_encoding(cell_file):
    """A build equals the MarkerArray of the same markers through the general writer."""
    cell = load_cell_text(CURVE_CELL) if cell_file == 'curve' else load_cell(cell_file)
    cm = m.CellMarkers(cell)
    rng = np.random.default_rng(3)
    for n in (0, 1, 7, 1000):
        part_type = rng.integers(0, len(cell.part_types), n).astype(np.uint16)
        x, y = rng.uniform(0, 6, n), rng.uniform(-0.2, 0.2, n)
        blocked = rng.random(len(cell.light_barriers)) < 0.5
        position = rng.uniform(0, 0.1, len(cell.actuators))
        data = cm.build(42_000_000, part_type, x, y, blocked, position)
        # the static prefix and the moving markers, all through _write_marker
        static_count = cm._static_count
        b = CdrBuilder()
        b.buf.extend(cm._static)
        moving = []
        for index, pt in enumerate(cell.part_types):
            mask = part_type == index
            pts = np.stack([x[mask], y[mask], np.full(int(mask.sum()), 0.5 * pt.height)], 1)
            scale = ((2 * pt.radius, 2 * pt.radius, pt.height) if pt.shape == 'disc'
                     else (pt.length, pt.width, pt.height))
            kind = m.SPHERE_LIST if pt.shape == 'disc' else m.CUBE_LIST
            moving.append(m._Marker(f'parts/{pt.name}', index, kind, scale=scale, points=pts,
                                    colour=m.PART_COLOURS[index % len(m.PART_COLOURS)]))
        for i, barrier in enumerate(cell.light_barriers):
            moving.append(m._Marker(
                'light_barriers', i, m.LINE_LIST, scale=(0.003, 0.0, 0.0),
                points=m._polyline_points([barrier.start, barrier.end], barrier.height),
                colour=m.BEAM_BLOCKED if blocked[i] else m.BEAM_FREE))
        for i, act in enumerate(cell.actuators):
            moving.append(m.CellMarkers._actuator(i, act, float(position[i])))
        b.buf[0:4] = (static_count + len(moving)).to_bytes(4, 'little')
        for marker in moving:
            m._write_marker(b, marker, 42_000_000, cell.settings.frame_id)
        assert data == b.message(), (cell_file, n)
