"""Read a plant YAML file into a validated :class:`~conveyor_twin.plant.model.Plant`.

Errors follow the cell loader's (:mod:`conveyor_twin.cell.loader`): a
:class:`~conveyor_twin.plant.errors.PlantError` names the plant file, the key path, the value
and what was expected; an invalid cell file raises the cell loader's error naming that file.

The format (every key in docs/plant.md)::

    plant: {name: line, namespace: plant, seed: 1}
    cells:
      - {name: infeed, file: infeed.yaml, placement: {x: 0.0, y: 0.0, yaw: 0.0}}
      - {name: main, file: default, namespace: main, placement: {x: 2.2}}
    links:
      - {name: infeed_main, from: {cell: infeed, sink: exit}, to: {cell: main, belt: main},
         delay: 0.1, capacity: 8}
"""

from dataclasses import replace
import math
from pathlib import Path
import re
from typing import Any, Dict, List, Optional, Tuple, Union

import yaml

from conveyor_twin.cell.errors import CellError
from conveyor_twin.cell.loader import KeyReader, load_cell
from conveyor_twin.cell.model import Cell, ZonePolicy
from conveyor_twin.plant.errors import PlantError
from conveyor_twin.plant.geometry import end_frame, end_rect
from conveyor_twin.plant.model import (Link, LinkEnd, MAX_CELLS, Placement, Plant, PlantCell)

#: ``file:`` value that names the embedded default cell.
DEFAULT_CELL = 'default'
#: Longest link delay [steps] (a day at 1 ms).
MAX_DELAY_STEPS = 86_400_000
_NAME = re.compile(r'[A-Za-z][A-Za-z0-9_]*\Z')
_NAME_EXPECTED = 'a name of letters, digits and _ starting with a letter (a ROS name token)'


class _PlantReader(KeyReader):
    """The cell loader's key reader, raising :class:`PlantError`."""

    def __init__(self, file: str, path: str, data: Any) -> None:
        if not isinstance(data, dict):
            raise PlantError(file, path or '<top level>', data, 'a mapping of keys to values')
        super().__init__(file, path, data)

    def fail(self, key: Union[str, int], value: Any, expected: str) -> PlantError:
        return PlantError(self.file, self.key_path(key), value, expected)

    def name(self, key: str, default: Any = None) -> str:
        value = self.raw(key, default) if default is not None else self.raw(key)
        if not isinstance(value, str) or not _NAME.match(value):
            raise self.fail(key, value, _NAME_EXPECTED)
        return value


def _placement(r: _PlantReader) -> Placement:
    p = Placement(x=r.number('x', 0.0, low=-1e6, high=1e6),
                  y=r.number('y', 0.0, low=-1e6, high=1e6),
                  yaw=r.number('yaw', 0.0, low=-2 * math.pi, high=2 * math.pi))
    r.done()
    return p


def _load_cell(r: _PlantReader, base: Path) -> Tuple[str, Cell]:
    file = r.raw('file')
    if not isinstance(file, str) or not file:
        raise r.fail('file', file, f'a cell file path (relative to the plant file) or '
                     f'{DEFAULT_CELL!r}')
    if file == DEFAULT_CELL:
        return file, load_cell(None)
    path = Path(file)
    if not path.is_absolute():
        path = base / path
    if not path.is_file():
        raise r.fail('file', file, f'an existing cell file (looked for {path})')
    return file, load_cell(path)


def _end(r: _PlantReader, cells: Dict[str, PlantCell], exit_side: bool) -> LinkEnd:
    name = r.raw('cell')
    if name not in cells:
        raise r.fail('cell', name, 'one of the plant\'s cells: ' + ', '.join(sorted(cells)))
    cell = cells[name].cell
    kinds = ('sink', 'belt') if exit_side else ('belt', 'region')
    given = [k for k in kinds if r.data.get(k) is not None]
    if len(given) != 1:
        where = 'a sink or a belt (its end)' if exit_side else 'a belt (its start) or a region'
        raise r.fail(kinds[0], {k: r.data.get(k) for k in kinds}, f'exactly one of {kinds}: '
                     f'{where}')
    kind = given[0]
    end = LinkEnd(cell=name)
    if kind == 'region':
        end = replace(end, region=r.rect('region'))
    else:
        value = r.string(kind)
        names = [x.name for x in (cell.sinks if kind == 'sink' else cell.belts)]
        if value not in names:
            raise r.fail(kind, value, f'a {kind} of cell {name!r}: ' + ', '.join(names))
        end = replace(end, **{kind: value})
    r.done()
    return end


def _macro_zone_at(cell: Cell, rect: Tuple[float, float, float, float]) -> Optional[str]:
    """Return the name of a macro or auto zone that ``rect`` overlaps, else None."""
    x0, y0, x1, y1 = rect
    for z in cell.zones:
        if z.policy == ZonePolicy.MICRO:
            continue
        a0, b0, a1, b1 = z.region
        if x0 < a1 and a0 < x1 and y0 < b1 and b0 < y1:
            return z.name
    return None


def _link(r: _PlantReader, cells: Dict[str, PlantCell], step: float) -> Link:
    name = r.name('name')
    source = _end(r.section('from', required=True), cells, exit_side=True)
    target = _end(r.section('to', required=True), cells, exit_side=False)
    has_s, has_k = r.data.get('delay') is not None, r.data.get('delay_steps') is not None
    if has_s == has_k:
        raise r.fail('delay', r.data.get('delay'), 'exactly one of delay [s] or delay_steps')
    if has_k:
        delay = r.integer('delay_steps', low=1, high=MAX_DELAY_STEPS)
    else:
        seconds = r.number('delay', low=step, high=MAX_DELAY_STEPS * step)
        delay = int(round(seconds / step))
        if abs(delay * step - seconds) > 1e-9 * max(1.0, seconds):
            raise r.fail('delay', seconds, f'a whole number of steps of {step:g} s')
    capacity = r.integer('capacity', 0, low=0, high=1_000_000)
    r.done()
    frames = (end_frame(cells[source.cell].cell, source, exit_side=True),
              end_frame(cells[target.cell].cell, target, exit_side=False))
    for end, key, frame in ((source, 'from', frames[0]), (target, 'to', frames[1])):
        zone = _macro_zone_at(cells[end.cell].cell, end_rect(frame))
        if zone is not None:
            raise r.fail(key, _end_text(end), f'an {"exit" if key == "from" else "entry"} '
                         f'in a micro zone: it overlaps zone {zone!r} (macro or auto); '
                         'density reaches a link as parts through a micro zone')
    src, dst = cells[source.cell].cell, cells[target.cell].cell
    type_map = []
    for p in src.part_types:
        try:
            type_map.append(dst.part_type_index(p.name))
        except KeyError:
            raise r.fail('to', _end_text(target), f'a cell that has part type {p.name!r} '
                         f'of cell {source.cell!r}') from None
    return Link(name=name, source=source, target=target, delay_steps=delay,
                capacity=capacity, type_map=tuple(type_map), exit=frames[0],
                entry=frames[1])


def _end_text(end: LinkEnd) -> Dict[str, Any]:
    out: Dict[str, Any] = {'cell': end.cell}
    for key in ('sink', 'belt', 'region'):
        value = getattr(end, key)
        if value is not None:
            out[key] = list(value) if key == 'region' else value
    return out


def plant_from_mapping(data: Any, source_file: str = '<memory>',
                       base: Optional[Path] = None) -> Plant:
    """Validate a parsed plant document; load its cells (relative to ``base``).

    :raises PlantError: on the first problem of the plant file.
    :raises CellError: if a cell file is invalid (naming that file).
    """
    base = Path('.') if base is None else base
    top = _PlantReader(source_file, '', data)
    head = top.section('plant', required=True)
    name = head.name('name')
    namespace = head.name('namespace', 'plant')
    plant_seed = head.integer('seed', None, low=0, high=2 ** 32 - 1)
    head.done()
    cells: Dict[str, PlantCell] = {}
    namespaces: Dict[str, int] = {}
    readers = top.items('cells')
    if len(readers) > MAX_CELLS:
        raise top.fail('cells', len(readers), f'at most {MAX_CELLS} cells (plant-wide ids)')
    step = None
    for index, r in enumerate(readers):
        cname = r.name('name')
        if cname in cells:
            raise r.fail('name', cname, 'a cell name not used before')
        file, cell = _load_cell(r, base)
        ns = r.name('namespace', cname)
        if ns in namespaces or ns == namespace:
            raise r.fail('namespace', ns, 'a namespace not used by another cell or the plant')
        namespaces[ns] = index
        default_seed = cell.settings.seed if plant_seed is None else plant_seed + index
        seed = r.integer('seed', default_seed, low=0, high=2 ** 32 - 1)
        placement = _placement(r.section('placement'))
        r.done()
        if step is None:
            step = cell.settings.step
        elif cell.settings.step != step:
            raise r.fail('file', file, f'a cell with the plant\'s step {step:g} s (the first '
                         f'cell\'s); this one steps {cell.settings.step:g} s')
        cells[cname] = PlantCell(name=cname, file=file, namespace=ns, cell=cell, seed=seed,
                                 placement=placement, index=index)
    links: List[Link] = []
    exits: Dict[Tuple[str, str], str] = {}
    for r in top.items('links', required=False):
        link = _link(r, cells, step)
        if any(k.name == link.name for k in links):
            raise r.fail('name', link.name, 'a link name not used before')
        key = (link.source.cell, link.source.sink or '~belt~' + (link.source.belt or ''))
        if key in exits:
            raise r.fail('from', _end_text(link.source), f'an exit no other link uses '
                         f'(link {exits[key]!r} does)')
        exits[key] = link.name
        links.append(link)
    top.done()
    _refuse_cycles(source_file, list(cells), links)
    linked_sinks: Dict[str, set] = {}
    for link in links:
        if link.source.sink is not None:
            linked_sinks.setdefault(link.source.cell, set()).add(link.source.sink)
    final = []
    for c in cells.values():
        drop = linked_sinks.get(c.name, set())
        if drop:
            sinks = tuple(s for s in c.cell.sinks if s.name not in drop)
            c = replace(c, cell=replace(c.cell, sinks=sinks))
        final.append(c)
    return Plant(source_file=source_file, name=name, namespace=namespace, step=float(step),
                 cells=tuple(final), links=tuple(links))


def _refuse_cycles(source_file: str, cells: List[str], links: List[Link]) -> None:
    """Raise if the links lead from a cell back to itself (a loop or a ring of cells).

    A plant is a directed acyclic graph of cells: the ids, the ledger and a restart's
    numbering follow parts downstream only (docs/plant.md, "Links").

    :raises PlantError: naming the link that closes the first cycle found, the cells and
        the links of the cycle.
    """
    out: Dict[str, List[Tuple[int, str]]] = {c: [] for c in cells}
    for i, link in enumerate(links):
        out[link.source.cell].append((i, link.target.cell))
    state: Dict[str, int] = {c: 0 for c in cells}   # 0 new, 1 on the path, 2 done
    path: List[Tuple[str, int]] = []                 # (cell, index of the link into it)

    def visit(cell: str) -> None:
        state[cell] = 1
        for i, nxt in out[cell]:
            if state[nxt] == 1:
                start = next(k for k, (c, _) in enumerate(path) if c == nxt)
                ring = path[start:]
                names = [c for c, _ in ring] + [nxt]
                through = [links[j].name for _, j in ring[1:]] + [links[i].name]
                raise PlantError(
                    source_file, f'links[{i}]', links[i].name,
                    'links without a cycle: this link closes the cycle '
                    + ' -> '.join(names) + ' (links ' + ', '.join(through) + '); a part '
                    'may not come back to a cell it left (no recirculation: see '
                    'docs/plant.md)')
            if state[nxt] == 0:
                path.append((nxt, i))
                visit(nxt)
                path.pop()
        state[cell] = 2

    for cell in cells:
        if state[cell] == 0:
            path.append((cell, -1))
            visit(cell)
            path.pop()


def load_plant(path: Union[str, Path]) -> Plant:
    """Load a plant file; cell files are resolved against its folder.

    :raises PlantError: if the file cannot be read or is not a valid plant.
    :raises CellError: if a cell file it names is invalid.
    """
    path = Path(path)
    try:
        text = path.read_text('utf-8')
    except (OSError, ValueError) as exc:
        raise PlantError(str(path), '<file>', str(exc), 'a readable UTF-8 YAML file') from None
    try:
        data = yaml.safe_load(text)
    except RecursionError:
        raise PlantError(str(path), '<document>', text[:40] + '...',
                         'YAML nested less deeply (the parser ran out of stack)') from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f'line {mark.line + 1}, column {mark.column + 1}' if mark else '<document>'
        raise PlantError(str(path), where, str(getattr(exc, 'problem', exc)),
                         'valid YAML') from None
    return plant_from_mapping(data, str(path), path.parent)


__all__ = ['CellError', 'load_plant', 'plant_from_mapping', 'PlantError']
