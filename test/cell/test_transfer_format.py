"""Transfer units and actuator force limits in the cell format: parsing, defaults, every
validation message, and the transfer example cell."""

import copy
import math
from pathlib import Path
from typing import Any, Dict

import pytest

from conveyor_twin.cell import CellError, cell_from_mapping, load_cell
from conveyor_twin.cell.model import ACTUATOR_KINDS, Actuator
from conveyor_twin.cli import main as cli_main

EXAMPLES = Path(__file__).resolve().parents[2] / 'conveyor_twin' / 'cell' / 'examples'

TRANSFER: Dict[str, Any] = {
    'name': 'xfer', 'kind': 'transfer', 'base': [1.5, 0.0], 'axis': [0.0, 2.0],
    'length': 0.4, 'width': 0.3, 'stroke': 0.02, 'max_speed': 0.1, 'surface_speed': 0.5,
}
DOC: Dict[str, Any] = {
    'cell': {'name': 'xfer'},
    'belts': [{'name': 'main', 'start': [0.0, 0.0], 'end': [3.0, 0.0], 'width': 0.4},
              {'name': 'side', 'start': [1.5, 0.2], 'end': [1.5, 2.0], 'width': 0.4}],
    'part_types': [{'name': 'box', 'shape': 'box', 'length': 0.1, 'width': 0.08,
                    'height': 0.05, 'mass': 0.3}],
    'actuators': [TRANSFER],
}


def _doc(**keys: Any) -> Dict[str, Any]:
    """Return DOC with the transfer's keys replaced (a value None removes the key)."""
    doc = copy.deepcopy(DOC)
    actuator = doc['actuators'][0]
    for key, value in keys.items():
        if value is None:
            actuator.pop(key, None)
        else:
            actuator[key] = value
    return doc


def _transfer(**keys: Any) -> Actuator:
    return cell_from_mapping(_doc(**keys), 'xfer.yaml').actuators[0]


def _error(**keys: Any) -> str:
    with pytest.raises(CellError) as info:
        cell_from_mapping(_doc(**keys), 'xfer.yaml')
    return str(info.value)


def test_a_transfer_is_read_with_its_defaults() -> None:
    assert 'transfer' in ACTUATOR_KINDS
    t = _transfer()
    assert t.kind == 'transfer' and not t.is_rotary
    assert t.axis == (0.0, 1.0)                       # normalised
    assert t.position_range == (0.0, 0.02) and t.initial_position == 0.0
    assert t.engage_height == pytest.approx(0.01)     # half the lift
    assert t.surface_speed == 0.5 and t.max_speed == 0.1
    assert t.friction == 0.5 and t.restitution == 0.2
    assert t.force_limit == math.inf


def test_a_transfer_may_give_its_travel_time_instead_of_its_speed() -> None:
    t = _transfer(max_speed=None, travel_time=0.25)
    assert t.max_speed == pytest.approx(0.02 / 0.25)
    t = _transfer(engage_height=0.02, friction=0.8, initial_position=0.02)
    assert (t.engage_height, t.friction, t.initial_position) == (0.02, 0.8, 0.02)


def test_other_kinds_keep_their_defaults_and_have_no_surface_speed() -> None:
    cell = load_cell(EXAMPLES / 'sorting.yaml')
    assert all(a.surface_speed == 0.0 and a.force_limit == math.inf and a.friction == 0.2
               for a in cell.actuators)


@pytest.mark.parametrize('keys, path, expected', [
    (dict(surface_speed=None), 'surface_speed: got None', 'this required key to be present'),
    (dict(surface_speed=0.0), 'surface_speed: got 0.0', 'a finite number in (0, 20]'),
    (dict(surface_speed=-0.5), 'surface_speed: got -0.5', 'a finite number in (0, 20]'),
    (dict(surface_speed=21), 'surface_speed: got 21', 'a finite number in (0, 20]'),
    (dict(stroke=None), 'stroke: got None', 'this required key to be present'),
    (dict(stroke=0.0), 'stroke: got 0.0', 'a finite number in (0, 10]'),
    (dict(engage_height=0.03), 'engage_height: got 0.03', 'a finite number in (0, 0.02]'),
    (dict(engage_height=0.0), 'engage_height: got 0.0', 'a finite number in (0, 0.02]'),
    (dict(initial_position=0.05), 'initial_position: got 0.05', 'a finite number in [0, 0.02]'),
    (dict(travel_time=0.2), 'max_speed: got 0.1', 'either max_speed or travel_time, not both'),
    (dict(max_speed=None, travel_time=0.0), 'travel_time: got 0.0',
     'a finite number in (0, 1000]'),
    (dict(max_speed=None, travel_time=1e-5), 'travel_time: got 1e-05',
     'at least 0.0002 s (a lift speed stroke / travel_time of at most 100 m/s)'),
    (dict(max_speed=None), 'max_speed: got None', 'this required key to be present'),
    (dict(force_limit=0), 'force_limit: got 0', 'a force in (0, 1e+07] [N], or .inf (unlimited)'),
    (dict(force_limit=-5.0), 'force_limit: got -5.0', 'a force in (0, 1e+07] [N]'),
    (dict(force_limit=2e7), 'force_limit: got 20000000.0', 'a force in (0, 1e+07] [N]'),
    (dict(force_limit=-math.inf), 'force_limit: got -inf', 'or .inf (unlimited)'),
    (dict(force_limit=math.nan), 'force_limit: got nan', 'or .inf (unlimited)'),
    (dict(force_limit='strong'), "force_limit: got 'strong'", 'or .inf (unlimited)'),
    (dict(force_limit=True), 'force_limit: got True', 'or .inf (unlimited)'),
    (dict(lift=0.02), 'lift: got 0.02', 'no such key here; known keys: axis, base'),
])
def test_every_transfer_error_names_file_key_value_and_range(keys: Dict[str, Any], path: str,
                                                            expected: str) -> None:
    msg = _error(**keys)
    assert msg.startswith(f'xfer.yaml: actuators[0].{path}'), msg
    assert expected in msg, msg


@pytest.mark.parametrize('kind, extra', [
    ('stopper', {}), ('pusher', {}),
    ('diverter', {'max_position': 0.8, 'stroke': None}),
])
@pytest.mark.parametrize('key, value', [('surface_speed', 0.5), ('travel_time', 0.2)])
def test_surface_speed_and_travel_time_belong_to_transfers_only(kind: str, extra: Dict[str, Any],
                                                               key: str, value: float) -> None:
    keys = {**extra, 'kind': kind, 'surface_speed': None, key: value}
    msg = _error(**keys)
    assert msg.startswith(f'xfer.yaml: actuators[0].{key}: got {value}; expected no such key '
                          'here'), msg


def test_force_limit_is_read_for_every_kind_and_inf_means_unlimited() -> None:
    assert _transfer(force_limit=250).force_limit == 250.0
    assert _transfer(force_limit=math.inf).force_limit == math.inf
    doc = _doc(kind='pusher', surface_speed=None, force_limit=80.0)
    assert cell_from_mapping(doc, 'p.yaml').actuators[0].force_limit == 80.0


def test_the_transfer_example_sends_parts_from_the_main_line_onto_the_side_line(capsys) -> None:
    path = EXAMPLES / 'transfer.yaml'
    cell = load_cell(path)
    main, side = cell.belts
    (xfer,) = cell.actuators
    assert xfer.kind == 'transfer' and xfer.initial_position == 0.0
    assert xfer.max_speed == pytest.approx(xfer.position_range[1] / 0.2)
    # the side line leaves the main belt at a right angle from its left edge
    mx, my = main.direction
    sx, sy = side.direction
    assert mx * sx + my * sy == 0.0 and mx * sy - my * sx > 0.0
    assert main.contains(side.start)
    # the footprint lies on the main belt, under the side line's mouth, carrying onto it
    hx, hy = 0.5 * xfer.length * xfer.axis[0], 0.5 * xfer.length * xfer.axis[1]
    wx, wy = -0.5 * xfer.width * xfer.axis[1], 0.5 * xfer.width * xfer.axis[0]
    bx, by = xfer.base
    corners = [(bx + i * hx + j * wx, by + i * hy + j * wy) for i in (-1, 1) for j in (-1, 1)]
    assert all(main.contains(c) for c in corners)
    assert xfer.axis == pytest.approx(side.direction)
    assert all(side.contains((c[0], side.start[1])) for c in corners)
    # light barriers on both lines, sinks at both ends
    on_main = [b.name for b in cell.light_barriers if main.contains(b.start)
               and main.contains(b.end)]
    on_side = [b.name for b in cell.light_barriers if side.contains(b.start)
               and side.contains(b.end)]
    assert on_main == ['lb_main_in', 'lb_main_out'] and on_side == ['lb_side']
    ends = {s.name: s.region for s in cell.sinks}

    def inside(point, rect) -> bool:
        return rect[0] <= point[0] <= rect[2] and rect[1] <= point[1] <= rect[3]

    assert inside(main.end, ends['main_exit']) and inside(side.end, ends['side_exit'])
    assert cli_main(['validate', str(path)]) == 0
    assert 'Actuators: xfer (transfer)' in capsys.readouterr().out
