"""The codec is public: one namespace ``wire.cdr``, and no module imports another package's
private names."""

import ast
from pathlib import Path

import numpy as np
import pytest

import conveyor_twin
from conveyor_twin.wire import cdr, decoders, encoders

ROOT = Path(conveyor_twin.__file__).resolve().parent


def test_cdr_exports_every_encoder_and_decoder():
    for module in (encoders, decoders):
        public = {name for name in vars(module) if not name.startswith('_')
                  and (name.startswith(('encode_', 'decode_'))
                       or name.endswith(('Encoder', 'Data')))}
        public -= {'FaultStateData'}  # with its encoder in wire.fault_state
        assert public - set(cdr.__all__) == set(), module.__name__
    assert all(hasattr(cdr, name) for name in cdr.__all__)


@pytest.mark.parametrize('zone', ['', 'buffer', 'zone-ü'])
def test_density_zone_reads_only_the_zone(zone):
    data = cdr.encode_density_grid(5, 'cell', 7, zone, 0.0, 0.0, 0.01, 3, 2,
                                   np.ones(6), 6e-4)
    assert cdr.density_zone(data) == zone == cdr.decode_density_grid(data).zone
    with pytest.raises(cdr.CdrError):
        cdr.density_zone(data[:20])


def _package(module: str) -> str:
    parts = module.split('.')
    return parts[1] if len(parts) > 1 and parts[0] == 'conveyor_twin' else parts[0]


def private_crossings(path: Path, root: Path = ROOT):
    """Yield ``name from module`` for every private name ``path`` imports from another
    package of conveyor_twin (a module or a name beginning with one underscore)."""
    own = path.relative_to(root).parts[0].removesuffix('.py')
    tree = ast.parse(path.read_text(encoding='utf-8'), filename=str(path))
    for node in ast.walk(tree):
        if not isinstance(node, ast.ImportFrom) or node.level or not node.module:
            continue
        if not node.module.startswith('conveyor_twin') or _package(node.module) == own:
            continue
        private = [p for p in node.module.split('.') if p.startswith('_')
                   and not p.startswith('__')]
        private += [a.name for a in node.names
                    if a.name.startswith('_') and not a.name.startswith('__')]
        for name in private:
            yield f'{path.relative_to(root)}: {name} from {node.module}'


def test_the_check_finds_crossings(tmp_path):
    (tmp_path / 'viz').mkdir()
    source = tmp_path / 'viz' / 'view.py'
    source.write_text('from conveyor_twin.record.series import _zone, load\n'
                      'from conveyor_twin.record import _scan\n'
                      'from conveyor_twin.viz.style import _own\n'
                      'from conveyor_twin.wire import cdr as _cdr\n')
    assert list(private_crossings(source, tmp_path)) == [
        'viz/view.py: _zone from conveyor_twin.record.series',
        'viz/view.py: _scan from conveyor_twin.record']


def test_no_private_name_crosses_packages():
    found = [c for p in sorted(ROOT.rglob('*.py')) if '__pycache__' not in p.parts
             for c in private_crossings(p)]
    assert found == []
