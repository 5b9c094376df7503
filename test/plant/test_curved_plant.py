"""A plant whose cell has a curved belt: link frames along the curve's ends, parts pass it."""

import math
import shutil
from pathlib import Path

import pytest

from conveyor_twin.cell import load_cell_text
from conveyor_twin.plant import geometry
from conveyor_twin.plant.loader import load_plant
from conveyor_twin.plant.model import LinkEnd
from conveyor_twin.plant.runner import PlantRunner

RES = Path(__file__).resolve().parents[1] / 'resources' / 'plant'

#: A quarter turn to the left: enters along +x at the origin, leaves along +y at (0.5, 0.5).
BEND = """
cell: {name: bend, step: 0.001, seed: 1}
belts:
  - name: bend
    curve: {centre: [0.0, 0.5], inner_radius: 0.4, outer_radius: 0.6, start_angle: -90,
            end_angle: 0, direction: ccw, guide_rails: true}
    speed: 1.0
    max_speed: 2.0
    acceleration: 5.0
    friction: 0.4
part_types:
  - {name: disc, shape: disc, radius: 0.01, height: 0.01, mass: 0.01}
micro: {capacity: 500}
"""

PLANT = """
plant: {name: curved, seed: 3}
cells:
  - {name: feeder, file: feeder.yaml}
  - {name: bend, file: bend.yaml, placement: {x: 0.5}}
  - {name: relay, file: relay.yaml, placement: {x: 1.1, y: 0.6, yaw: 1.5707963267948966}}
links:
  - {name: feed_bend, from: {cell: feeder, sink: exit}, to: {cell: bend, belt: bend},
     delay_steps: 40}
  - {name: bend_relay, from: {cell: bend, belt: bend}, to: {cell: relay, belt: main},
     delay: 0.03}
"""


def test_the_link_frames_of_a_curved_belt_follow_its_tangent():
    cell = load_cell_text(BEND)
    bend = cell.belts[0]
    entry = geometry.end_frame(cell, LinkEnd('bend', belt='bend'), exit_side=False)
    leave = geometry.end_frame(cell, LinkEnd('bend', belt='bend'), exit_side=True)
    assert (entry.x, entry.y) == pytest.approx(bend.start, abs=1e-12)
    assert entry.yaw == pytest.approx(0.0, abs=1e-12)               # along +x
    assert (leave.x, leave.y) == pytest.approx(bend.end, abs=1e-12)
    assert leave.yaw == pytest.approx(0.5 * math.pi)                  # along +y
    assert entry.half_width == leave.half_width == pytest.approx(0.5 * bend.width)
    # clockwise: the same arc run the other way round heads the other way
    cw = load_cell_text(BEND.replace('start_angle: -90,\n            end_angle: 0, '
                                     'direction: ccw',
                                     'start_angle: 0,\n            end_angle: -90, '
                                     'direction: cw'))
    assert geometry.heading(cw.belts[0], at_end=False) == pytest.approx(-0.5 * math.pi)
    end = geometry.heading(cw.belts[0], at_end=True)
    assert (math.cos(end), math.sin(end)) == pytest.approx((-1.0, 0.0), abs=1e-12)  # along -x


@pytest.fixture(scope='module')
def plant(tmp_path_factory):
    folder = tmp_path_factory.mktemp('curved_plant')
    for name in ('feeder.yaml', 'relay.yaml'):
        shutil.copy(RES / name, folder / name)
    (folder / 'bend.yaml').write_text(BEND)
    (folder / 'plant.yaml').write_text(PLANT)
    return load_plant(folder / 'plant.yaml')


def test_parts_ride_the_curve_into_the_next_cell(plant):
    runner = PlantRunner(plant, check_balance=True)
    for _ in range(60):
        runner.step(50)
        ledger = runner.ledger()
        assert ledger.residual == 0.0, ledger.text()
        if ledger.links['bend_relay'].inserted >= 3:
            break
    ledger = runner.ledger()
    assert ledger.links['feed_bend'].inserted > 3, ledger.text()
    assert ledger.links['bend_relay'].inserted >= 3, ledger.text()
    assert ledger.entered == ledger.in_cells + ledger.in_links + ledger.left


def test_the_plant_drawing_shows_the_curve(plant, tmp_path):
    from conveyor_twin.viz.plant_drawing import plot_plant
    out = tmp_path / 'plant.png'
    assert plot_plant(plant, str(out), width=8.0, dpi=40) == str(out)
    assert out.stat().st_size > 0
