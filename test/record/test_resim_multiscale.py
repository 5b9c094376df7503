"""A multiscale run re-simulates bit for bit, though its edges are not recorded in time order.

A step's ``light_barrier_edges`` are published micro barriers first, then those in ``macro``
zones, each stamped with its own time; a closed recording is read in log-time order, so a
macro-zone edge earlier in the step than a micro one is read before it, against the sequence
numbers. The run is recorded the way ``conveyor-twin run --record`` records it (the twin's
frames through :class:`~conveyor_twin.record.sink.RecordingSink`), without ROS.
"""

from importlib import resources

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.output.producers import CoordinatorOutput, MacroOutput, MicroOutput
from conveyor_twin.record import reader
from conveyor_twin.record.resimulate import resimulate
from conveyor_twin.record.sink import RecordingSink
from conveyor_twin.record.writer import McapRecorder

CELL = resources.files('conveyor_twin.cell') / 'examples' / 'multiscale.yaml'
SEED = 1
STEPS = 2500  # 2.5 s; with this seed the first step with edges out of time order is 1857
EDGES = '/light_barrier_edges'


def record(path):
    """Record STEPS steps of the multiscale cell (no markers); return the cell."""
    cell = load_cell(str(CELL))
    built = build_twin(cell, seed=SEED)
    output = TwinOutput([CoordinatorOutput(built.twin), MicroOutput(built.micro),
                         MacroOutput(built.macro)])
    built.twin.step_listeners.append(output.on_step)
    recorder = McapRecorder(str(path), cell_yaml=CELL.read_text(), seed=SEED,
                            step_ns=built.twin.dt_ns,
                            metadata={'recorded_by': 'test', 'markers_rate': '0.0'})
    output.subscribe(RecordingSink(recorder))
    try:
        built.twin.step(STEPS)
    finally:
        stats = recorder.close()
    assert stats.dropped == 0
    return cell


def test_multiscale_recording_with_edges_out_of_time_order_resimulates(tmp_path):
    path = tmp_path / 'multiscale.mcap'
    record(path)
    edges = list(reader.read_messages(str(path), topics=[EDGES]))
    numbers = [m.sequence for m in edges]
    assert numbers != sorted(numbers), 'no step with edges out of time order: nothing tested'
    assert sorted(numbers) == list(range(1, len(edges) + 1))

    report = resimulate(str(path))
    assert report.ok, str(report.difference)
    assert report.steps == STEPS
    assert report.compared[EDGES] == len(edges) > 100
    assert report.compared['/parts'] == report.compared['/clock'] == STEPS
