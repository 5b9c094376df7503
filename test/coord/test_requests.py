"""What a spawn or a reset request may contain (:mod:`conveyor_twin.coord.requests`)."""

import math

import numpy as np
import pytest
import yaml

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.loader import default_cell_text
from conveyor_twin.coord.requests import check_reset, check_spawn, RequestRejected


def test_a_good_spawn_names_its_type_and_defaults_yaw() -> None:
    cell = load_cell()
    name = cell.part_types[-1].name
    request = check_spawn(cell, name, [1.0, 1.2], [0.0, 0.1], [])
    assert request.type_index == len(cell.part_types) - 1 and request.count == 2
    assert np.array_equal(request.yaw, np.zeros(2))
    assert request.placed_message() == f'placed 2 {name} part(s)'


@pytest.mark.parametrize('args, text', [
    (('bolt', [1.0], [0.0], [0.0]), "unknown part_type 'bolt' (known: "),
    ((None, [1.0, 1.1], [0.0], [0.0]), 'same non-zero length (got 2, 1, 1)'),
    ((None, [], [], []), 'same non-zero length (got 0, 0, 0)'),
    ((None, [1.0], [0.0], [0.0, 1.0]), 'same non-zero length (got 1, 1, 2)'),
    ((None, [1.0], [math.nan], [0.0]), 'poses must be finite numbers'),
    ((None, [1.0], [0.0], [math.inf]), 'poses must be finite numbers'),
])
def test_a_bad_spawn_is_rejected_with_its_reason(args, text) -> None:
    cell = load_cell()
    part_type = args[0] or cell.part_types[0].name
    with pytest.raises(RequestRejected) as info:
        check_spawn(cell, part_type, *args[1:])
    assert text in str(info.value)


def test_reset_keeps_or_loads_a_cell_with_the_same_interface(tmp_path) -> None:
    cell = load_cell()
    assert check_reset(cell, '') is cell
    same = tmp_path / 'same.yaml'
    same.write_text(default_cell_text())
    assert check_reset(cell, str(same)).settings.name == cell.settings.name
    with pytest.raises(RequestRejected, match='nonexistent.yaml'):
        check_reset(cell, str(tmp_path / 'nonexistent.yaml'))
    d = yaml.safe_load(default_cell_text())
    d['belts'][0]['name'] = 'other'
    other = tmp_path / 'other.yaml'
    other.write_text(yaml.safe_dump(d))
    with pytest.raises(RequestRejected, match='needs a restart of the twin'):
        check_reset(cell, str(other))


@pytest.mark.parametrize('x, y, text', [
    (4.5, 0.9, "part 0 (spacer) at x = 4.5 m, y = 0.9 m is not on a belt (allowed: a centre on "
               "belt 'main': x 0..6 m, y -0.25..0.25 m)"),
    (-0.1, 0.0, 'is not on a belt'),
    (6.2, 0.0, 'is not on a belt'),
    (1.0, 0.247, "overlaps wall 'wall_left_in'"),
    (2.9, 0.1, "overlaps deflector 'deflector'"),
])
def test_a_spawn_off_the_belts_or_into_an_obstacle_is_rejected(x, y, text) -> None:
    with pytest.raises(RequestRejected) as info:
        check_spawn(load_cell(), 'spacer', [1.0, x], [0.0, y], [])
    assert text.replace('part 0', 'part 1') in str(info.value)
    assert str(info.value).endswith('nothing placed')


def test_every_shipped_cell_takes_a_part_on_each_belt_centre() -> None:
    from pathlib import Path
    import conveyor_twin.cell as cells
    files = sorted((Path(cells.__file__).parent / 'examples').glob('*.yaml'))
    assert files
    for path in [None] + files:
        cell = load_cell(str(path) if path else None)
        part = min(cell.part_types, key=lambda p: p.bounding_radius)
        for belt in cell.belts:
            (x0, y0), (x1, y1) = belt.start, belt.end
            xs, ys = [x0 + 0.3 * (x1 - x0)], [y0 + 0.3 * (y1 - y0)]
            try:
                check_spawn(cell, part.name, xs, ys, [])
            except RequestRejected as exc:  # a belt may carry an obstacle there: say which
                assert 'overlaps' in str(exc), (path, str(exc))


def test_spawns_on_a_curved_belt_follow_its_annular_sector() -> None:
    from pathlib import Path
    import conveyor_twin.cell as cells
    cell = load_cell(Path(cells.__file__).parent / 'examples' / 'l_line.yaml')
    bend = cell.belts[1]
    mx, my = bend.centre_line(3)[1]              # the middle of the curve's centre line
    assert check_spawn(cell, 'can', [mx], [my], []).count == 1
    with pytest.raises(RequestRejected) as info:  # inside the inner arc: on no belt
        check_spawn(cell, 'can', [2.2], [0.4], [])
    assert ("belt 'bend': radius 0.4..0.8 m about (2, 0.6) from -90 deg through 90 deg"
            in str(info.value))
    with pytest.raises(RequestRejected, match="overlaps wall 'bend_rail_outer'"):
        cx, cy = bend.curve.centre
        check_spawn(cell, 'can', [cx + 0.78 * math.cos(-0.8)], [cy + 0.78 * math.sin(-0.8)], [])
