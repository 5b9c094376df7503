"""Fuzzing the cell loader: a mutated cell gives a Cell of valid values or a CellError, no other.

Each input is the default cell (or the micro benchmark's cell) with one to three seeded
mutations: a key or list item deleted, a value of another type, NaN, +-inf, huge floats and
integers beyond a float, an unknown key, a deeply nested value, a name with NUL or control
characters, a very long string. Every input goes through ``cell_from_mapping`` and, where it
can be written as YAML, through ``load_cell_text``. Any exception other than
:class:`~conveyor_twin.cell.CellError` fails, and so does an accepted cell holding a value no
cell may hold (:func:`invalid_values`). A large file (a thousand obstacles and as many
barriers) and deeply nested YAML text are tried beside.

:data:`FAST_INPUTS` inputs run by default; the slow-marked test runs :data:`SLOW_INPUTS`.
"""

import copy
import dataclasses
import math
import random
from typing import Any, Iterator, List, Tuple

import pytest
import yaml

from conveyor_twin.cell import CellError, default_cell_text
from conveyor_twin.cell.loader import (cell_from_mapping, COORDINATE_LIMIT, load_cell_text)

SEED = 20261123
FAST_INPUTS = 100
SLOW_INPUTS = 3000
WEIRD_NUMBERS = (math.nan, math.inf, -math.inf, 1e308, -1e308, 10 ** 400, -10 ** 400, 2 ** 63,
                 2 ** 64, -2 ** 63 - 1, 5e-324, 0, -0.0, -1, 1e-9)
WEIRD_VALUES = (None, True, False, '', 'x', 'a\x00b', 'tab\there', 'x' * 10_000, [], {},
                [1.0], [1.0, 2.0, 3.0], {'a': 1}, [[0.0, 0.0]], b'bytes'.decode())


def bench_cell_text() -> str:
    from importlib import resources
    return resources.files('conveyor_twin.cell').joinpath('bench_micro.yaml').read_text()


BASES = (yaml.safe_load(default_cell_text()), yaml.safe_load(bench_cell_text()))


def dump(doc: Any) -> str:
    """Write ``doc`` as YAML (libyaml's emitter where available)."""
    return yaml.dump(doc, Dumper=getattr(yaml, 'CSafeDumper', yaml.SafeDumper))


def paths(node: Any, prefix: Tuple = ()) -> Iterator[Tuple]:
    """Yield the path (keys and indices) of every value below ``node`` (down to 8 levels)."""
    if len(prefix) >= 8:
        return
    items = node.items() if isinstance(node, dict) else (
        enumerate(node) if isinstance(node, list) else ())
    for key, value in items:
        yield prefix + (key,)
        yield from paths(value, prefix + (key,))


def containers(node: Any, prefix: Tuple = ()) -> Iterator[Tuple]:
    """Yield the path of every mapping below and including ``node`` (down to 8 levels)."""
    if len(prefix) >= 8:
        return
    if isinstance(node, dict):
        yield prefix
    items = node.items() if isinstance(node, dict) else (
        enumerate(node) if isinstance(node, list) else ())
    for key, value in items:
        yield from containers(value, prefix + (key,))


def get(node: Any, path: Tuple) -> Any:
    for key in path:
        node = node[key]
    return node


def nested(depth: int, rng: random.Random) -> Any:
    value: Any = rng.choice((1.0, 'x', None))
    for _ in range(depth):
        value = [value] if rng.random() < 0.5 else {'k': value}
    return value


def mutate(doc: Any, rng: random.Random) -> str:
    """Apply one random mutation to ``doc`` in place; return what it did."""
    all_paths = list(paths(doc))
    path = rng.choice(all_paths)
    parent, key = get(doc, path[:-1]), path[-1]
    op = rng.randrange(7)
    if op == 0:
        del parent[key]
        return f'delete {path}'
    if op == 1:
        parent[key] = rng.choice(WEIRD_VALUES)
        return f'retype {path}'
    if op == 2:
        number_paths = [p for p in all_paths
                        if isinstance(get(doc, p), (int, float))
                        and not isinstance(get(doc, p), bool)] or [path]
        path = rng.choice(number_paths)
        get(doc, path[:-1])[path[-1]] = rng.choice(WEIRD_NUMBERS)
        return f'number {path}'
    if op == 3:
        target = rng.choice(list(containers(doc)))
        get(doc, target)[rng.choice(('unknown', 'Name', 'speed ', 'zz'))] = rng.choice(
            WEIRD_VALUES + WEIRD_NUMBERS)
        return f'unknown key in {target}'
    if op == 4:
        parent[key] = nested(rng.choice((20, 100, 1000)), rng)
        return f'nest {path}'
    if op == 5:
        string_paths = [p for p in all_paths if isinstance(get(doc, p), str)] or [path]
        path = rng.choice(string_paths)
        get(doc, path[:-1])[path[-1]] = rng.choice(('', 'a\x00b', 'a\nb', '\x7f', 'y' * 10 ** 4,
                                                    ' ', 'ü'))
        return f'string {path}'
    lists = [p for p in all_paths if isinstance(get(doc, p), list) and get(doc, p)] or [path]
    path = rng.choice(lists)
    items = get(doc, path)
    if isinstance(items, list) and items:
        item = rng.choice(items)
        items.append(dict(item) if isinstance(item, dict) else item)   # a duplicate name
    return f'duplicate in {path}'


def invalid_values(node: Any, where: str = 'cell') -> List[str]:
    """Return what an accepted :class:`Cell` holds that no cell may: non-finite or huge
    numbers (but an actuator's unlimited force_limit), coordinates beyond the limit, booleans as
    numbers, empty or unprintable strings."""
    found: List[str] = []
    if dataclasses.is_dataclass(node):
        for f in dataclasses.fields(node):
            found += invalid_values(getattr(node, f.name), f'{where}.{f.name}')
    elif isinstance(node, (tuple, list)):
        for i, item in enumerate(node):
            found += invalid_values(item, f'{where}[{i}]')
    elif isinstance(node, bool):
        pass
    elif isinstance(node, float):
        if where.endswith('.force_limit') and node == math.inf:
            return found
        if not math.isfinite(node) or abs(node) > 1e12:
            found.append(f'{where} = {node!r}')
    elif isinstance(node, int):
        if abs(node) > 2 ** 63:
            found.append(f'{where} = {node!r}')
    elif isinstance(node, str):
        if where.endswith('source_file'):
            return found
        if not node or not node.isprintable():
            found.append(f'{where} = {node[:20]!r}')
    return found


def check(doc: Any, label: str) -> str:
    """Load ``doc`` both ways; return 'accepted' or 'refused'; fail on anything else."""
    outcomes = []
    try:
        cell = cell_from_mapping(doc, '<fuzz>')
    except CellError:
        outcomes.append('refused')
    else:
        bad = invalid_values(cell)
        assert not bad, f'{label}: accepted invalid values {bad[:5]}'
        assert all(abs(c) <= COORDINATE_LIMIT for b in cell.belts for p in (b.start, b.end)
                   for c in p), label
        outcomes.append('accepted')
    try:
        text = dump(doc)
    except (RecursionError, yaml.YAMLError):
        return outcomes[0]  # not writable as YAML (too deep for the dumper)
    try:
        load_cell_text(text, '<fuzz.yaml>')
    except CellError:
        outcomes.append('refused')
    else:
        outcomes.append('accepted')
    assert outcomes[0] == outcomes[1] or 'nest' in label, (label, outcomes)
    return outcomes[0]


def fuzz(count: int, seed: int) -> dict:
    rng = random.Random(seed)
    tally = {'accepted': 0, 'refused': 0}
    for i in range(count):
        doc = copy.deepcopy(BASES[i % len(BASES)])
        done = [mutate(doc, rng) for _ in range(rng.randint(1, 3))]
        tally[check(doc, f'input {i} (seed {seed}): ' + '; '.join(done))] += 1
    return tally


def test_fuzzed_cells_are_valid_or_refused_with_a_cell_error():
    tally = fuzz(FAST_INPUTS, SEED)
    print(f'cell loader fuzz: {FAST_INPUTS} inputs, {tally}')
    assert tally['refused'] > FAST_INPUTS // 2 and tally['accepted'] > 0


@pytest.mark.slow
def test_fuzzed_cells_many():
    tally = fuzz(SLOW_INPUTS, SEED + 1)
    print(f'cell loader fuzz: {SLOW_INPUTS} inputs, {tally}')
    assert tally['refused'] > 0 and tally['accepted'] > 0


def test_a_large_cell_file_loads():
    doc = copy.deepcopy(BASES[0])
    doc['obstacles'] += [{'name': f'peg{i}', 'kind': 'peg', 'center': [0.01 * i, 0.2],
                          'radius': 0.002} for i in range(1000)]
    doc['light_barriers'] += [{'name': f'lb{i}', 'start': [0.001 * i, -0.25],
                               'end': [0.001 * i, 0.25], 'height': 0.005} for i in range(1000)]
    text = dump(doc)
    assert len(text) > 150_000
    cell = load_cell_text(text, '<large.yaml>')
    assert len(cell.obstacles) == len(BASES[0]['obstacles']) + 1000
    doc['light_barriers'].append(dict(doc['light_barriers'][-1]))   # one duplicate name
    with pytest.raises(CellError, match=r"light_barriers\[\d+\]\.name: got 'lb999'"):
        load_cell_text(dump(doc), '<large.yaml>')


@pytest.mark.parametrize('depth', [50, 5000, 200_000])
def test_deeply_nested_text_is_a_cell_error(depth):
    for text in ('cell: ' + '[' * depth + ']' * depth, 'cell: ' + '{a: ' * depth + '1'
                 + '}' * depth):
        with pytest.raises(CellError, match=r'^<fuzz>: (cell|cell\.name|<document>): got'):
            load_cell_text(text, '<fuzz>')


@pytest.mark.parametrize('path', ['a\x00b.yaml', '/', '\x00', 'x' * 5000])
def test_unreadable_cell_paths_are_cell_errors(path):
    from conveyor_twin.cell import load_cell
    with pytest.raises(CellError, match=r'<file>: got .*expected a readable UTF-8 YAML file'):
        load_cell(path)


@pytest.mark.parametrize('value', [10 ** 400, -10 ** 400, math.inf, 1e308, 1001.0])
def test_coordinates_beyond_the_limit_are_refused(value):
    doc = copy.deepcopy(BASES[0])
    doc['belts'][0]['end'] = [value, 0.0]
    with pytest.raises(CellError, match=r'belts\[0\]\.end: got .*within \+-1000'):
        cell_from_mapping(doc, '<fuzz>')
    doc = copy.deepcopy(BASES[0])
    doc['sinks'][0]['region'] = [0.0, 0.0, value, 1.0]
    with pytest.raises(CellError, match=r'sinks\[0\]\.region: got .*within \+-1000'):
        cell_from_mapping(doc, '<fuzz>')
