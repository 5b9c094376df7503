"""``conveyor-twin plc-map``: a cell's tag map as Markdown or CSV."""

import csv
import io

from conveyor_twin.cli import main
from conveyor_twin.cell import load_cell
from conveyor_twin.plc.tags import tag_map
from test.plc.test_tags import PACKAGE_CELLS


def test_default_cell_as_markdown(capsys) -> None:
    assert main(['plc-map']) == 0
    out = capsys.readouterr().out
    assert out == tag_map(load_cell()).to_markdown()
    assert '| Belts/main/SpeedSetpoint | Double | m/s | read/write | holding | 2 |' in out


def test_a_cell_file_as_csv_to_a_file(tmp_path, capsys) -> None:
    target = tmp_path / 'map.csv'
    cell = str(PACKAGE_CELLS / 'examples' / 'sorting.yaml')
    assert main(['plc-map', cell, '--format', 'csv', '--output', str(target)]) == 0
    assert str(target) in capsys.readouterr().out
    rows = list(csv.reader(io.StringIO(target.read_text())))
    assert len(rows) == len(tag_map(load_cell(cell)).tags) + 1


def test_an_invalid_cell_exits_1_with_the_loaders_message(tmp_path, capsys) -> None:
    bad = tmp_path / 'bad.yaml'
    bad.write_text('cell: {name: x}\nbelts: 3\n')
    assert main(['plc-map', str(bad)]) == 1
    err = capsys.readouterr().err
    assert err.startswith('invalid cell: ') and 'bad.yaml' in err
    assert main(['plc-map', str(tmp_path / 'missing.yaml')]) == 1
    assert 'missing.yaml' in capsys.readouterr().err


def test_an_unwritable_output_exits_1(tmp_path, capsys) -> None:
    assert main(['plc-map', '--output', str(tmp_path / 'no' / 'such' / 'dir.md')]) == 1
    assert 'cannot write' in capsys.readouterr().err
