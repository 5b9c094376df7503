"""The axes of the combination matrix and the checks shared by its tests (no ROS imports).

Cells: every shipped cell (straight ones, and those with a curved belt or a transfer unit) and
the cells of the example plant. Faults: one of each family of ``docs/faults.md`` (barrier,
drive, command, material, stream), built for a cell from its own names and armed as a scenario
file by step, so that every output of a run sees the same faults at the same steps. Checks: a stream is *live* when it has exactly one message for every step
of the run except the steps a ``stream_outage`` silenced it (known from the run's ``faults``
stream), and two outputs *agree* when they carry the same bytes for the same stamps.
"""

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Dict, Iterable, List, Optional, Sequence, Set, Tuple

import yaml

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import Cell
from conveyor_twin.wire import cdr
from conveyor_twin.wire.decoders import decode_fault_state

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = Path(ROOT, 'conveyor_twin', 'cell')
PLANT = ROOT / 'examples' / 'plant' / 'plant.yaml'


@lru_cache(maxsize=None)
def _load(path: Path) -> Cell:
    return load_cell(str(path))


@dataclass(frozen=True)
class CellCase:
    """A cell of the matrix: a test id and its file."""

    key: str
    path: Path
    #: the cell is one of the example plant's
    plant_cell: bool = False

    @property
    def cell(self) -> Cell:
        """The loaded cell (loaded once)."""
        return _load(self.path)


STRAIGHT_CELLS = (
    CellCase('default', SHIPPED / 'default_cell.yaml'),
    CellCase('multiscale', SHIPPED / 'examples' / 'multiscale.yaml'),
    CellCase('sorting', SHIPPED / 'examples' / 'sorting.yaml'),
    CellCase('merge', SHIPPED / 'examples' / 'merge.yaml'),
)
#: The shipped cells with a curved belt or a transfer unit.
CURVED_CELLS = (
    CellCase('l_line', SHIPPED / 'examples' / 'l_line.yaml'),
    CellCase('transfer', SHIPPED / 'examples' / 'transfer.yaml'),
)
SHIPPED_CELLS = STRAIGHT_CELLS + CURVED_CELLS
PLANT_CELLS = tuple(CellCase(f'plant_{name}', PLANT.parent / f'{name}.yaml', True)
                    for name in ('infeed', 'deflector', 'sorter', 'buffer'))
CELLS = SHIPPED_CELLS + PLANT_CELLS
#: The order in which the cells take the streams of :data:`OUTAGE_ROTATION` (cells added
#: later come last, so every cell keeps the stream it had).
_ROTATION_ORDER = STRAIGHT_CELLS + PLANT_CELLS + CURVED_CELLS

#: Steps of one run of the matrix [1]; every fault below starts and ends within them.
STEPS = 400
#: Per-step streams (absolute topic names as recordings and Foxglove name them).
PER_STEP = ('/parts', '/light_barriers', '/belt_states', '/actuator_states', '/clock')
#: Streams a ``stream_outage`` silences, one per cell of the matrix in turn.
OUTAGE_ROTATION = ('light_barrier_edges', 'density', 'actuator_states', 'parts',
                   'light_barriers', 'belt_states', '/clock', 'parts')
FAMILIES = ('barrier', 'drive', 'command', 'material', 'stream')
#: The drive family's second member, for cells with actuators.
ACTUATION = 'actuation'
#: A belt command every run sends (step at which it takes effect, speed fraction of the max).
COMMAND_STEP = 150
COMMAND_FRACTION = 0.6


def outage_stream(case: CellCase) -> str:
    """Return the stream the ``stream_outage`` of ``case`` silences (one with messages)."""
    stream = OUTAGE_ROTATION[_ROTATION_ORDER.index(case) % len(OUTAGE_ROTATION)]
    if stream == 'density' and not macro_zones(case.cell):
        return 'parts'
    return stream


def macro_zones(cell: Cell) -> List[str]:
    """Return the zones that publish a density grid: one ``density`` message per step each
    (every zone that is not ``micro``)."""
    from conveyor_twin.cell.model import ZonePolicy
    return [z.name for z in cell.zones if z.policy is not ZonePolicy.MICRO]


def families_of(case: CellCase) -> Tuple[str, ...]:
    """Return the fault families of ``case``: :data:`FAMILIES`, and an actuator fault where the
    cell has actuators."""
    return FAMILIES + ((ACTUATION,) if case.cell.actuators else ())


def fault_entries(case: CellCase, families: Optional[Sequence[str]] = None) -> List[dict]:
    """Return scenario entries (``docs/faults.md``) of one fault per family for ``case``.

    Every fault starts and ends within :data:`STEPS`: barrier at step 40 (chatter, 100 steps),
    drive at 80 (belt stall, 100 steps; and the first actuator 5 mm or mrad off from step 60
    for 200 steps where the cell has one), command at 120 (belt commands delayed, 200 steps),
    material at 20 (a surging source, or parts falling off the whole cell where it has no
    source, 300 steps), stream at 100 (one stream silenced for 50 steps, while the barrier
    chatters: edges happen while ``light_barrier_edges`` is silent).
    """
    cell = case.cell
    families = families_of(case) if families is None else families
    entries = {
        'barrier': {'kind': 'barrier_chatter', 'target': cell.light_barriers[0].name,
                    'params': {'frequency': 50.0}, 'at': {'step': 40}, 'duration': 0.1},
        'drive': {'kind': 'belt_stall', 'target': cell.belts[0].name, 'at': {'step': 80},
                  'duration': 0.1},
        'command': {'kind': 'command_delay', 'target': 'belt_command',
                    'params': {'delay': 0.05}, 'at': {'step': 120}, 'duration': 0.2},
        'stream': {'kind': 'stream_outage', 'target': outage_stream(case),
                   'at': {'step': 100}, 'duration': 0.05},
    }
    if cell.actuators:
        entries[ACTUATION] = {'kind': 'actuator_offset', 'target': cell.actuators[0].name,
                              'params': {'offset': 0.005}, 'at': {'step': 60},
                              'duration': 0.2}
    if cell.sources:
        entries['material'] = {'kind': 'source_surge', 'target': cell.sources[0].name,
                               'params': {'factor': 5.0}, 'at': {'step': 20}, 'duration': 0.3}
    else:
        x0, x1, y0, y1 = _extent(cell)
        entries['material'] = {'kind': 'parts_vanish', 'target': '',
                               'params': {'x0': x0, 'y0': y0, 'x1': x1, 'y1': y1},
                               'at': {'step': 20}, 'duration': 0.3}
    return [entries[f] for f in families]


def _extent(cell: Cell) -> Tuple[float, float, float, float]:
    x0, y0, x1, y1 = cell.bounds
    return x0, x1, y0, y1


def write_scenario(path: Path, case: CellCase,
                   families: Optional[Sequence[str]] = None) -> Path:
    """Write the scenario of :func:`fault_entries` to ``path``; return it."""
    families = families_of(case) if families is None else families
    text = yaml.safe_dump({'name': f'{case.key}: {", ".join(families)}',
                           'faults': fault_entries(case, families)}, sort_keys=False)
    path.write_text(text)
    return path


def belt_command(case: CellCase) -> Tuple[str, float]:
    """Return the belt command every run sends at :data:`COMMAND_STEP` (name, speed [m/s])."""
    belt = case.cell.belts[0]
    return belt.name, round(COMMAND_FRACTION * belt.max_speed, 3)


# -- liveness and agreement ------------------------------------------------------------------
def silenced_steps(fault_states: Iterable[bytes], step_ns: int, steps: int) -> Dict[str, Set[int]]:
    """Return, per stream, the steps a ``stream_outage`` silenced, from a run's ``faults``
    messages (each states the active set from its stamp on)."""
    states = sorted((decode_fault_state(data) for data in fault_states),
                    key=lambda s: s.stamp_ns)
    out: Dict[str, Set[int]] = {}
    for i, state in enumerate(states):
        first = state.stamp_ns // step_ns
        last = states[i + 1].stamp_ns // step_ns - 1 if i + 1 < len(states) else steps
        for fault in state.active:
            if fault.kind == 'stream_outage':
                name = fault.target if fault.target.startswith('/') else '/' + fault.target
                out.setdefault(name, set()).update(range(first, last + 1))
    return out


def step_gaps(messages: Sequence[bytes], step_ns: int, steps: int, silenced: Set[int],
              per_step: int = 1) -> Optional[str]:
    """Return why a per-step stream is not live (None if it is): it must carry ``per_step``
    messages stamped at every step 1..``steps`` except the silenced ones, and none of those."""
    counts: Dict[int, int] = {}
    for data in messages:
        stamp = cdr.stamp_of(data)
        if stamp % step_ns:
            return f'a message stamped {stamp} ns, between steps'
        counts[stamp // step_ns] = counts.get(stamp // step_ns, 0) + 1
    wanted = {k: per_step for k in range(1, steps + 1) if k not in silenced}
    if counts == wanted:
        return None
    missing = sorted(k for k in wanted if counts.get(k, 0) < per_step)
    extra = sorted(k for k in counts if counts[k] > wanted.get(k, 0))
    return (f'{len(missing)} steps without their message (first {missing[:5]}), '
            f'{len(extra)} steps with messages that should not be there (first {extra[:5]})')


def by_stamp(messages: Iterable[bytes]) -> Dict[int, List[bytes]]:
    """Group messages by their stamp [ns], in order."""
    out: Dict[int, List[bytes]] = {}
    for data in messages:
        out.setdefault(cdr.stamp_of(data), []).append(data)
    return out
