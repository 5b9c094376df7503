"""`conveyor-twin plot PLANT.yaml` draws the whole plant: every cell at its placement, every
link an arrow from its exit to its entry, to scale, every cell and link named."""

from pathlib import Path

import pytest

from conveyor_twin.cli.plot import main as plot_main
from conveyor_twin.plant.loader import load_plant
from conveyor_twin.viz.plant_drawing import (cell_outline, is_plant_file, link_points,
                                             plant_figure, text_box)

EXAMPLE = Path(__file__).resolve().parents[2] / 'examples' / 'plant' / 'plant.yaml'


def test_plot_of_a_plant_file_writes_one_png(tmp_path, capsys):
    out = tmp_path / 'plant.png'
    assert plot_main([str(EXAMPLE), '-o', str(out)]) == 0
    assert out.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and out.stat().st_size > 20_000
    assert f'wrote {out}' in capsys.readouterr().out


def test_a_cell_file_is_not_a_plant_file():
    assert is_plant_file(str(EXAMPLE))
    assert not is_plant_file(str(EXAMPLE.parent / 'sorter.yaml'))
    assert not is_plant_file('default') and not is_plant_file('run.mcap')


def test_the_drawing_places_cells_and_links_in_the_plant_frame():
    plant = load_plant(EXAMPLE)
    fig, ax = plant_figure(plant, dpi=60)
    try:
        texts = [t.get_text() for t in ax.texts]
        for c in plant.cells:
            assert any(t.startswith(c.name) for t in texts), texts
        for k in plant.links:
            assert any(t.startswith(k.name + '\n') for t in texts), texts
        # the sorter's outline lies at its placement, x 7.4 m on
        xs = [p[0] for p in cell_outline(plant, plant.cell('sorter'))]
        assert min(xs) == pytest.approx(7.4, abs=0.1)
        # every link runs from its exit cell to its entry cell (downstream, to the right)
        for link in plant.links:
            (x0, _), (x1, _) = link_points(plant, link)
            src = [p[0] for p in cell_outline(plant, plant.cell(link.source.cell))]
            dst = [p[0] for p in cell_outline(plant, plant.cell(link.target.cell))]
            assert min(src) <= x0 <= max(src) and min(dst) <= x1 <= max(dst)
            assert x1 > x0
        x0, x1 = ax.get_xlim()
        assert x0 < 0.0 and x1 > 10.4     # the whole line, buffers included
        # no two names overlap
        renderer = fig.canvas.get_renderer()
        boxes = [text_box(t, renderer) for t in ax.texts]
        for i, a in enumerate(boxes):
            for b in boxes[i + 1:]:
                assert not a.overlaps(b)
    finally:
        from matplotlib import pyplot as plt
        plt.close(fig)


def test_plot_of_a_bad_plant_file_exits_1(tmp_path, capsys):
    bad = tmp_path / 'plant.yaml'
    bad.write_text('plant: {name: x}\ncells:\n  - {name: a, file: missing.yaml}\n')
    assert plot_main([str(bad), '-o', str(tmp_path / 'p.png')]) == 1
    assert 'missing.yaml' in capsys.readouterr().err
