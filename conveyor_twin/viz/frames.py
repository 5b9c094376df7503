"""Sample a recording at animation frame times: the latest message of each stream per frame.

One pass over the recording in log-time order. Part states, density grids and actuator states
are decoded only for the messages a frame shows (the latest at or before its time); light
barriers and belt states are kept as time series sampled at ``SERIES_PER_FRAME`` times the
frame rate (for the plots under the scene). Times are simulation time [s].
"""

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

import numpy as np

from conveyor_twin.cell import CellError, load_cell_text
from conveyor_twin.cell.model import Cell
from conveyor_twin.record import reader
from conveyor_twin.wire.decoders import decode_actuator_states, decode_belt_states
from conveyor_twin.record.errors import RecordingError
from conveyor_twin.record.series import ACTUATORS, BARRIERS, BELTS, DENSITY, PARTS
from conveyor_twin.wire import cdr

#: Samples of the barrier and belt series per animation frame [1].
SERIES_PER_FRAME = 4
_NS = 1e-9


@dataclass
class Frame:
    """What one animation frame shows; ``t`` [s], positions [m], yaw [rad]."""

    t: float
    parts: Optional[cdr.PartStatesData] = None
    density: Dict[str, cdr.DensityGridData] = field(default_factory=dict)
    blocked: Optional[np.ndarray] = None
    actuator_position: Optional[np.ndarray] = None


@dataclass
class Timeline:
    """A sampled series: names, t [s] (n,), values (n, len(names)); commanded for belts."""

    names: Tuple[str, ...] = ()
    t: List[float] = field(default_factory=list)
    values: List[np.ndarray] = field(default_factory=list)
    commanded: List[np.ndarray] = field(default_factory=list)

    def arrays(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (t, values, commanded) as arrays ((0, 0) when empty)."""
        if not self.t:
            return np.zeros(0), np.zeros((0, 0)), np.zeros((0, 0))
        com = np.vstack(self.commanded) if self.commanded else np.zeros((len(self.t), 0))
        return np.asarray(self.t), np.vstack(self.values).astype(float), com


@dataclass
class RecordingFrames:
    """Frames of a recording plus its cell (None if it carries no valid ``cell.yaml``)."""

    path: str
    cell: Optional[Cell]
    frames: List[Frame]
    barriers: Timeline
    belts: Timeline
    start_s: float
    end_s: float


def frame_times(start_s: float, end_s: float, fps: float, speed: float) -> np.ndarray:
    """Return the simulation times of the frames: every ``speed / fps`` s from ``start_s``.

    :param fps: frames per second of the animation [1/s].
    :param speed: simulated seconds per second of animation (speed-up) [1].
    """
    step = speed / fps
    count = int(np.floor((end_s - start_s) / step + 1e-9)) + 1
    return start_s + step * np.arange(max(count, 1))


def recording_cell(path: str) -> Optional[Cell]:
    """Return the cell attached to a recording, or None if it has none or it is not valid."""
    try:
        text = reader.read_attachment(path, 'cell.yaml').decode('utf-8')
        return load_cell_text(text, f'{path}:cell.yaml')
    except (RecordingError, CellError, UnicodeDecodeError):
        return None


def _topics_by_type(summary: dict) -> Dict[str, str]:
    return {topic: t['type'] for topic, t in summary['topics'].items()
            if t['type'] in (PARTS, DENSITY, BARRIERS, BELTS, ACTUATORS) and t['count']}


def load_frames(path: str, *, fps: float, speed: float, start_s: Optional[float] = None,
                end_s: Optional[float] = None) -> RecordingFrames:
    """Read a recording into animation frames.

    :param path: a closed recording.
    :param fps: frames per second of the animation [1/s].
    :param speed: simulated seconds per second of animation [1].
    :param start_s: first frame's simulation time [s] (default: the recording's start).
    :param end_s: last simulation time shown [s] (default: the recording's end).
    :raises RecordingError: if the file cannot be read, has no part states, or the time range
        is empty.
    """
    summary = reader.info(path)
    kinds = _topics_by_type(summary)
    if PARTS not in kinds.values():
        types = ', '.join(sorted(kinds.values())) or 'none of the twin\'s streams'
        raise RecordingError(f'{path} has no part states to animate (no {PARTS} messages; '
                             f'it holds {types})')
    rec_start, rec_end = summary['start_ns'] * _NS, summary['end_ns'] * _NS
    start = rec_start if start_s is None else start_s
    end = rec_end if end_s is None else min(end_s, rec_end)
    if not rec_start <= start <= end:
        raise RecordingError(f'{path}: time range {start:g}..{end:g} s is empty or outside the '
                             f'recording ({rec_start:g}..{rec_end:g} s)')
    times = frame_times(start, end, fps, speed)
    sample_dt = speed / fps / SERIES_PER_FRAME
    frames = [Frame(float(t)) for t in times]
    latest: Dict[str, Tuple[str, bytes]] = {}
    barriers, belts = Timeline(), Timeline()
    next_series = {BARRIERS: start, BELTS: start}
    k = 0

    def snapshot(frame: Frame) -> None:
        for kind, data in latest.values():
            if kind == PARTS and frame.parts is None:
                frame.parts = cdr.decode_part_states(data)
            elif kind == DENSITY:
                grid = cdr.decode_density_grid(data)
                frame.density[grid.zone] = grid
            elif kind == BARRIERS:
                frame.blocked = cdr.decode_light_barrier_states(data)[4]
            elif kind == ACTUATORS:
                frame.actuator_position = decode_actuator_states(data).actual

    for m in reader.read_messages(path, topics=list(kinds)):
        t = m.log_time * _NS
        while k < len(frames) and t > frames[k].t + 1e-12:
            snapshot(frames[k])
            k += 1
        if t > end + 1e-12:
            break
        kind = kinds[m.topic]
        key = m.topic if kind != DENSITY else m.topic + '#' + _zone_key(m.data)
        latest[key] = (kind, m.data)
        if kind in next_series and t >= next_series[kind] - 1e-12:
            next_series[kind] = t + sample_dt
            if kind == BARRIERS:
                _, _, _, names, blocked, _ = cdr.decode_light_barrier_states(m.data)
                _append(barriers, t, names, blocked, None)
            else:
                b = decode_belt_states(m.data)
                _append(belts, t, b.names, b.actual, b.commanded)
    while k < len(frames):
        snapshot(frames[k])
        k += 1
    return RecordingFrames(path, recording_cell(path), frames, barriers, belts, start, end)


def _append(series: Timeline, t: float, names: Tuple[str, ...], values: np.ndarray,
            commanded: Optional[np.ndarray]) -> None:
    if series.t and names != series.names:
        return  # another cell after a reset: keep the first set of names
    series.names = tuple(names)
    series.t.append(t)
    series.values.append(np.asarray(values, float))
    if commanded is not None:
        series.commanded.append(np.asarray(commanded, float))


def _zone_key(data: bytes) -> str:
    return cdr.density_zone(data)
