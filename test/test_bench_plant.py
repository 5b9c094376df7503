"""``bench plant``: the benchmark's plants are valid chains, and a tiny run of both layouts
reports figures in range with a balanced ledger (not its wall-clock times)."""

import json

import pytest

from conveyor_twin.bench import plant as bench
from conveyor_twin.plant.loader import load_plant


@pytest.mark.parametrize('cells', [1, 2, 8])
def test_written_plants_are_chains(tmp_path, cells):
    plant = load_plant(bench.write_plant(tmp_path, cells))
    assert [c.name for c in plant.cells] == [f'c{k}' for k in range(cells)]
    assert [(k.source.cell, k.target.cell) for k in plant.links] == [
        (f'c{k}', f'c{k + 1}') for k in range(cells - 1)]
    assert all(k.delay_steps == round(bench.DELAY / plant.step) for k in plant.links)
    assert plant.cells[0].cell.sources and not any(c.cell.sources for c in plant.cells[1:])


def test_stops_scaling_finds_the_first_halving():
    rows = {str(n): {'one_process': {'cell_steps_per_s': v},
                     'processes': {'cell_steps_per_s': 100.0 * n}}
            for n, v in ((1, 100.0), (2, 120.0), (4, 150.0), (8, 160.0))}
    assert bench.stops_scaling(rows) == {'one_process': 4, 'processes': 0}


@pytest.mark.ros
def test_tiny_run_of_both_layouts(capsys):
    assert bench.main(['--sizes', '1,2', '--duration', '0.5', '--json']) == 0
    report = json.loads(capsys.readouterr().out)
    assert report['duration_s'] == 0.5 and set(report['sizes']) == {'1', '2'}
    for n, row in report['sizes'].items():
        for layout in ('one_process', 'processes'):
            figures = row[layout]
            assert figures['rtf'] > 0.0 and figures['cell_steps_per_s'] > 0.0
            assert figures['parts_per_s'] == pytest.approx(figures['left'] / figures['wall_s'])
        assert row['speedup'] == pytest.approx(row['processes']['rtf']
                                               / row['one_process']['rtf'])
    # the same plant, seed and steps: the same parts left the line in both layouts
    for row in report['sizes'].values():
        assert row['one_process']['left'] == row['processes']['left']
    # seeded: parts of the one cell's first 0.2 s reached its exit in 0.5 s
    assert report['sizes']['1']['one_process']['left'] > 0
    assert set(report['stops_scaling']) == {'one_process', 'processes'}
