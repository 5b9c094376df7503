"""What a PLC reads: the tags' values, from the twin's frames, for servers on their own threads.

:class:`PlcState` is a frame sink. On the stepping thread its :meth:`~PlcState.on_frame` only
stores references (one tuple: the frame's number, step, time, the step's input, the
light-barrier, belt and actuator states' bytes; the fault state's bytes when the frame has
them) and appends the step's light-barrier edges to a deque: no decoding, no lock. A server
thread calls :meth:`~PlcState.refresh` at its own rate; it drains the edges (so a pulse
shorter than the server's period is still counted), decodes the latest states and returns an
immutable :class:`PlcView` with every tag's value; its edge counts are exactly those of the
frames up to the one whose step, time and blocked flags it shows. Several servers may refresh
at once: one lock around the drain and the counters, never taken by ``on_frame``.

Edge counters and the last edge times count from the state's creation and keep counting
across a reset of the twin; step, time, blocked flags and the rest follow the twin.
"""

from collections import deque
import threading
from typing import Any, Callable, Deque, Dict, List, Mapping, Optional, Sequence, Tuple

from conveyor_twin.cell.model import Cell
from conveyor_twin.plc.lockstep import StepHandshake
from conveyor_twin.plc.tags import DEFAULT_TICK_STEPS, MODE_CODES, Tag, tag_map, TagMap, Value
from conveyor_twin.wire.decoders import (decode_actuator_states, decode_belt_states,
                                         decode_fault_state, decode_light_barrier_edge,
                                         decode_light_barrier_states)

_NO_INPUT = (0, 0, 0, None, None, None, None)


class PlcView:
    """Every tag's value at one moment (immutable; from :meth:`PlcState.refresh`).

    :ivar step: step index of the latest frame [1].
    :ivar time_ns: its simulation time [ns].
    :ivar values: one value per tag of :attr:`PlcState.tags`, in its order (OPC UA
        meaning: times in s, ``Mode`` as its name).
    """

    __slots__ = ('step', 'time_ns', 'values', '_index', '_edges')

    def __init__(self, step: int, time_ns: int, values: Tuple[Value, ...],
                 index: Mapping[str, int], edges: Mapping[str, Optional[int]]) -> None:
        self.step = step
        self.time_ns = time_ns
        self.values = values
        self._index = index
        self._edges = edges

    def value(self, tag: Tag) -> Value:
        """Return the value of ``tag`` (bool, int, float [SI units, times in s] or str)."""
        return self.values[self._index[tag.path]]

    def edge_ns(self, tag: Tag) -> Optional[int]:
        """Return the time of the edge a ``LastRisingTime`` / ``LastFallingTime`` tag shows
        [ns, simulation time] (its SourceTimestamp), None before the first edge."""
        return self._edges.get(tag.path)


class PlcState:
    """The tags' current values, fed by the twin's frames (a frame sink).

    :param cell: the twin's cell.
    :param mode: the time mode (``realtime``, ``fast`` or ``lockstep``).
    :param counters: the part ledger (``ComposedTwin.counters``: ``macro_balance_*`` keys, or
        ``micro_*``/``macro_*``, or ``entered``/``left``/``in_flight``); None: zeros.
    :param setpoints: the belts' target speeds [m/s], used when the frames carry no
        ``belt_states``; None: the cell's initial speeds.
    :param rejected: the number of rejected commands (``lambda: book.rejected_total``);
        None: 0.
    :param handshake: the lockstep handshake whose tick and state the ``Lockstep/*`` tags show.
    """

    def __init__(self, cell: Cell, *, mode: str,
                 counters: Optional[Callable[[], Mapping[str, float]]] = None,
                 setpoints: Optional[Callable[[], Sequence[float]]] = None,
                 rejected: Optional[Callable[[], int]] = None,
                 handshake: Optional[StepHandshake] = None) -> None:
        mode = str(getattr(mode, 'value', mode))
        if mode not in MODE_CODES:
            raise ValueError(f'PlcState: mode {mode!r} is not one of {", ".join(MODE_CODES)}')
        self.cell = cell
        self.mode = mode
        self.map: TagMap = tag_map(cell)
        self.tags: Tuple[Tag, ...] = self.map.tags
        self.counters = counters
        self.setpoints = setpoints
        self.rejected = rejected
        self.handshake = handshake
        self._index: Dict[str, int] = {t.path: i for i, t in enumerate(self.tags)}
        self._barrier_index = {b.name: i for i, b in enumerate(cell.light_barriers)}
        # written by on_frame only (one assignment each)
        self._frames = 0
        self._latest: Tuple[Any, ...] = _NO_INPUT
        self._faults: Optional[bytes] = None
        self._edges: Deque[Tuple[int, Tuple[Tuple[int, bytes], ...]]] = deque()
        # read and written under the lock by refresh
        self._lock = threading.Lock()
        n = len(cell.light_barriers)
        self._rising = [0] * n
        self._falling = [0] * n
        self._edge_blocked = [False] * n
        self._last_rising: List[Optional[int]] = [None] * n
        self._last_falling: List[Optional[int]] = [None] * n
        self._decoded: Tuple[Any, ...] = (None, None)  # (latest tuple, its decoded states)
        self._fault_text: Tuple[Optional[bytes], int, str] = (None, 0, '')

    # --- the stepping thread ---
    def on_frame(self, frame: Any) -> None:
        """Keep references to the step's states and queue its edges (O(1), no lock).

        The edges are queued before the states are published, numbered with the frame, so a
        refresh counts exactly the edges of the frames up to the one whose states it shows.
        """
        n = self._frames + 1
        self._frames = n
        if frame.edges:
            self._edges.append((n, tuple(frame.edges)))
        if frame.faults is not None:
            self._faults = frame.faults
        self._latest = (n, frame.step, frame.time_ns, frame.input, frame.light_barriers,
                        frame.belt_states, frame.actuator_states)

    # --- server threads ---
    def refresh(self) -> PlcView:
        """Take the edges since the last refresh and return every tag's current value."""
        # the handshake first: a view that shows tick k done then holds every frame of tick k
        lockstep = self._lockstep()
        with self._lock:
            latest = self._latest
            self._drain(latest[0])
            decoded = self._decode(latest)
            faults = self._fault_summary(self._faults)
            return self._view(latest, decoded, faults, lockstep)

    def _lockstep(self) -> Dict[str, Any]:
        handshake = self.handshake
        if handshake is None:
            return {'done': True, 'done_tick': 0, 'tick': 0, 'tick_steps': DEFAULT_TICK_STEPS}
        return {'done': handshake.done, 'done_tick': handshake.done_tick,
                'tick': handshake.tick, 'tick_steps': handshake.tick_steps}

    def _drain(self, upto: int) -> None:
        """Count the edges of the frames up to number ``upto``."""
        edges = self._edges
        index = self._barrier_index
        while edges and edges[0][0] <= upto:
            for stamp, data in edges.popleft()[1]:
                edge = decode_light_barrier_edge(data)
                i = index.get(edge.name)
                if i is None:
                    continue  # not a barrier of this cell: the producer names only those
                if edge.blocked:
                    self._rising[i] += 1
                    self._last_rising[i] = stamp
                else:
                    self._falling[i] += 1
                    self._last_falling[i] = stamp
                self._edge_blocked[i] = edge.blocked

    def _decode(self, latest: Tuple[Any, ...]) -> Tuple[Any, ...]:
        """Return (blocked, belt setpoints, belt actual, actuator targets, positions, stalls,
        loads) of the latest frame (decoded once per frame)."""
        if self._decoded[0] is latest:
            return self._decoded[1]
        cell = self.cell
        _, _, _, inp, barriers, belts, actuators = latest
        if barriers is not None:
            blocked = tuple(bool(b) for b in decode_light_barrier_states(barriers)[4])
        else:
            blocked = tuple(self._edge_blocked)
        if belts is not None:
            states = decode_belt_states(belts)
            setpoint = tuple(float(v) for v in states.commanded)
            actual = tuple(float(v) for v in states.actual)
        else:
            setpoint = tuple(float(v) for v in self.setpoints()) if self.setpoints else \
                tuple(b.speed for b in cell.belts)
            actual = tuple(float(v) for v in inp.belt_speed) if inp is not None else \
                tuple(0.0 for _ in cell.belts)
        if actuators is not None:
            states = decode_actuator_states(actuators)
            target = tuple(float(v) for v in states.commanded)
            position = tuple(float(v) for v in states.actual)
            stalled = tuple(bool(v) for v in states.stalled)
            load = tuple(float(v) for v in states.load)
        else:
            target = tuple(a.initial_position for a in cell.actuators)
            position = tuple(float(v) for v in inp.actuator_position) if inp is not None \
                else target
            stalled = tuple(False for _ in cell.actuators)
            load = tuple(0.0 for _ in cell.actuators)
        out = (blocked, setpoint, actual, target, position, stalled, load)
        self._decoded = (latest, out)
        return out

    def _fault_summary(self, data: Optional[bytes]) -> Tuple[int, str]:
        if self._fault_text[0] is not data:
            if data is None:
                self._fault_text = (None, 0, '')
            else:
                active = decode_fault_state(data).active
                text = '; '.join(f'{f.id} {f.kind} {f.target}' for f in active)
                self._fault_text = (data, len(active), text)
        return self._fault_text[1], self._fault_text[2]

    def _view(self, latest: Tuple[Any, ...], decoded: Tuple[Any, ...],
              faults: Tuple[int, str], lockstep: Dict[str, Any]) -> PlcView:
        step, time_ns = latest[1], latest[2]
        blocked, setpoint, actual, target, position, stalled, load = decoded
        ledger = ledger_values(self.counters() if self.counters is not None else {})
        twin = {'time': time_ns * 1e-9, 'step': step, 'mode': self.mode,
                'faults_active': faults[0], 'active_faults': faults[1],
                'rejected_writes': int(self.rejected()) if self.rejected is not None else 0}
        per_barrier = {'blocked': blocked, 'rising': self._rising, 'falling': self._falling}
        edge_times = {'last_rising': self._last_rising, 'last_falling': self._last_falling}
        per_belt = {'setpoint': setpoint, 'actual': actual}
        per_actuator = {'target': target, 'position': position, 'stalled': stalled,
                        'load': load}
        values: List[Value] = []
        edges: Dict[str, Optional[int]] = {}
        for tag in self.tags:
            source = tag.source
            group = source[0]
            if group == 'barrier':
                _, i, what = source
                if what in edge_times:
                    ns = edge_times[what][i]
                    edges[tag.path] = ns
                    values.append(ns * 1e-9 if ns is not None else 0.0)
                else:
                    values.append(per_barrier[what][i])
            elif group == 'belt':
                values.append(per_belt[source[2]][source[1]])
            elif group == 'actuator':
                values.append(per_actuator[source[2]][source[1]])
            elif group == 'ledger':
                values.append(ledger[source[1]])
            elif group == 'lockstep':
                values.append(lockstep[source[1]])
            else:
                values.append(twin[source[1]])
        return PlcView(step, time_ns, tuple(values), self._index, edges)


def ledger_values(counters: Mapping[str, float]) -> Dict[str, float]:
    """Return the cell's part ledger (``entered``, ``left``, ``in_flight`` [parts]) from a
    twin's counters: the scale coupling's ledger when there is one (``macro_balance_*``),
    else the sum of the scales' (``micro_*`` + ``macro_*``), else plain keys."""
    if 'macro_balance_entered' in counters:
        c = {k[len('macro_balance_'):]: v for k, v in counters.items()
             if k.startswith('macro_balance_')}
        return {'entered': float(c['entered']), 'left': float(c['left']),
                'in_flight': float(c.get('micro', 0.0) + c.get('macro', 0.0)
                                   + c.get('pending', 0.0))}
    out = {}
    for key in ('entered', 'left', 'in_flight'):
        if f'micro_{key}' in counters or f'macro_{key}' in counters:
            out[key] = float(counters.get(f'micro_{key}', 0.0)
                             + counters.get(f'macro_{key}', 0.0))
        else:
            out[key] = float(counters.get(key, 0.0))
    return out
