"""Time series of a recording for plots and checks, decoded with the fast CDR decoders.

Topics are recognised by their type, so namespaced recordings work alike. Times are the log
times (simulation time) in seconds. Part states can be thinned (every ``part_stride``-th
message); density grids are decoded only for the snapshots asked for (the message nearest to
each requested time, per zone); light barriers, edges, belts and actuators are kept in full.
"""

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from conveyor_twin.record import reader
from conveyor_twin.wire import cdr

_MSGS = 'conveyor_twin_msgs/msg/'
PARTS = _MSGS + 'PartStates'
DENSITY = _MSGS + 'DensityGrid'
BARRIERS = _MSGS + 'LightBarrierStates'
EDGES = _MSGS + 'LightBarrierEdge'
BELTS = _MSGS + 'BeltStates'
ACTUATORS = _MSGS + 'ActuatorStates'
_NS = 1e-9


@dataclass
class PartSamples:
    """Flattened part samples: one entry per (sampled message, part); t [s], x, y [m]."""

    t: np.ndarray
    id: np.ndarray
    x: np.ndarray
    y: np.ndarray


@dataclass
class NamedSeries:
    """Per-name series: t [s] (n,), commanded and actual (n, len(names))."""

    names: Tuple[str, ...]
    t: np.ndarray
    commanded: np.ndarray
    actual: np.ndarray


@dataclass
class BarrierSeries:
    """Light barrier states: t [s] (n,), blocked (n, len(names)) and the edges."""

    names: Tuple[str, ...]
    t: np.ndarray
    blocked: np.ndarray
    edges: List[Tuple[float, str, bool]] = field(default_factory=list)


@dataclass
class Series:
    """What :func:`load` extracted; None where the recording has no such topic."""

    parts: Optional[PartSamples] = None
    density: Dict[float, List[cdr.DensityGridData]] = field(default_factory=dict)
    barriers: Optional[BarrierSeries] = None
    belts: Optional[NamedSeries] = None
    actuators: Optional[NamedSeries] = None
    start_s: float = 0.0
    end_s: float = 0.0


class _Pairs:
    def __init__(self) -> None:
        self.names: Tuple[str, ...] = ()
        self.t: List[float] = []
        self.a: List[np.ndarray] = []
        self.b: List[np.ndarray] = []

    def add(self, t: float, names: Tuple[str, ...], a: np.ndarray, b: np.ndarray) -> None:
        if names != self.names:
            if self.t:  # the set of names changed (another cell): keep the first set
                return
            self.names = names
        self.t.append(t)
        self.a.append(a)
        self.b.append(b)

    def series(self) -> Optional[NamedSeries]:
        if not self.t:
            return None
        return NamedSeries(self.names, np.asarray(self.t), np.vstack(self.a),
                           np.vstack(self.b))


def load(path: str, *, part_stride: int = 1,
         density_times: Sequence[float] = ()) -> Series:
    """Read a recording into time series.

    :param path: closed recording.
    :param part_stride: keep every k-th PartStates message [1].
    :param density_times: simulation times of the density snapshots [s].
    :raises RecordingError: if the recording cannot be read.
    :raises CdrError: on a malformed message.
    """
    summary = reader.info(path)
    by_type: Dict[str, List[str]] = {}
    for topic, t in summary['topics'].items():
        by_type.setdefault(t['type'], []).append(topic)
    wanted = {topic: type_name for type_name in (PARTS, DENSITY, BARRIERS, EDGES, BELTS,
                                                 ACTUATORS)
              for topic in by_type.get(type_name, ())}
    out = Series(start_s=summary['start_ns'] * _NS, end_s=summary['end_ns'] * _NS)
    parts_t, parts_id, parts_x, parts_y = [], [], [], []
    part_count = 0
    nearest: Dict[Tuple[float, str], Tuple[float, bytes]] = {}
    bar_t, bar_b, bar_names = [], [], ()
    edges: List[Tuple[float, str, bool]] = []
    belts, actuators = _Pairs(), _Pairs()
    targets = [float(t) for t in density_times]
    for m in reader.read_messages(path, topics=list(wanted)):
        kind = wanted[m.topic]
        t = m.log_time * _NS
        if kind == PARTS:
            part_count += 1
            if (part_count - 1) % part_stride:
                continue
            p = cdr.decode_part_states(m.data)
            parts_t.append(np.full(len(p.id), t))
            parts_id.append(p.id)
            parts_x.append(p.x)
            parts_y.append(p.y)
        elif kind == DENSITY and targets:
            zone = cdr.density_zone(m.data)
            for target in targets:
                best = nearest.get((target, zone))
                if best is None or abs(t - target) < best[0]:
                    nearest[(target, zone)] = (abs(t - target), m.data)
        elif kind == BARRIERS:
            _, _, _, names, blocked, _ = cdr.decode_light_barrier_states(m.data)
            if not bar_t:
                bar_names = names
            if names == bar_names:
                bar_t.append(t)
                bar_b.append(blocked)
        elif kind == EDGES:
            e = cdr.decode_light_barrier_edge(m.data)
            edges.append((e.stamp_ns * _NS, e.name, e.blocked))
        elif kind == BELTS:
            b = cdr.decode_belt_states(m.data)
            belts.add(t, b.names, b.commanded, b.actual)
        elif kind == ACTUATORS:
            a = cdr.decode_actuator_states(m.data)
            actuators.add(t, a.names, a.commanded, a.actual)
    if parts_t:
        out.parts = PartSamples(np.concatenate(parts_t), np.concatenate(parts_id),
                                np.concatenate(parts_x), np.concatenate(parts_y))
    for (target, _), (_, data) in sorted(nearest.items()):
        out.density.setdefault(target, []).append(cdr.decode_density_grid(data))
    if bar_t or edges:
        out.barriers = BarrierSeries(tuple(bar_names), np.asarray(bar_t),
                                     np.vstack(bar_b) if bar_b else np.zeros((0, 0), bool),
                                     edges)
    out.belts = belts.series()
    out.actuators = actuators.series()
    return out


def pick_parts(parts: PartSamples, count: int) -> np.ndarray:
    """Return up to ``count`` part ids, the longest-lived first, in id order.

    :param parts: the samples.
    :param count: how many ids [1].
    """
    ids, n = np.unique(parts.id, return_counts=True)
    order = np.argsort(-n, kind='stable')[:count]
    return np.sort(ids[order])
