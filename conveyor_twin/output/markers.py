"""``visualization_msgs/MarkerArray`` CDR for RViz and Foxglove, built from numpy at viewer rate.

Building Marker objects in Python costs ~8 ms for 1000 points (measured here), which would
break the 1 ms step; this writes the CDR directly: the fixed geometry once, and at every
build the moving markers with one ``struct`` call per group of fields (~40 us for 1000 parts,
during which the markers thread holds the interpreter lock the stepping thread needs). Parts
are drawn as one SPHERE_LIST (discs, scaled to diameter x diameter x height) or CUBE_LIST
(boxes, axis-aligned: lists carry no per-point orientation) per part type; the cell's belts (a
straight one a flat CUBE, a curved one its annular sector as a TRIANGLE_LIST within
:data:`CHORD_ERROR` of the arcs), obstacles, light barriers (red while blocked) and actuators
(at their current position; a transfer unit a box as high as its lift, dark blue from its
engage height on, pale blue below) are drawn too.
"""

import math
import struct
from typing import List, Sequence, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.wire.builder import CdrBuilder, ENCAPSULATION_LE, stamp_parts, string_bytes

CUBE, SPHERE, CYLINDER, LINE_STRIP, LINE_LIST, CUBE_LIST, SPHERE_LIST = 1, 2, 3, 4, 5, 6, 7
TRIANGLE_LIST = 11
#: Largest distance [m] between a curved belt's drawn edge and its arc.
CHORD_ERROR = 1e-4
_F32x4 = struct.Struct('<4f')
_STAMP = struct.Struct('<iI')
_IDS = struct.Struct('<iii')           # id, type, action
_POSE_SCALE = struct.Struct('<10d')    # position, orientation (quaternion), scale
_U32 = struct.Struct('<I')
_ZEROS = tuple(bytes(k) for k in range(8))
_LIFETIME_LOCKED = bytes(9)            # int32 0, uint32 0, bool false

PART_COLOURS = [(0.75, 0.75, 0.8, 1.0), (0.9, 0.6, 0.2, 1.0), (0.3, 0.7, 0.3, 1.0),
                (0.3, 0.5, 0.9, 1.0)]
BELT_COLOUR = (0.15, 0.15, 0.15, 1.0)
OBSTACLE_COLOUR = (0.7, 0.72, 0.75, 1.0)
BEAM_FREE = (0.1, 0.9, 0.1, 1.0)
BEAM_BLOCKED = (1.0, 0.1, 0.1, 1.0)
ACTUATOR_COLOUR = (0.95, 0.8, 0.1, 1.0)
TRANSFER_UP = (0.12, 0.44, 0.71, 1.0)
TRANSFER_DOWN = (0.62, 0.79, 0.91, 1.0)


class _Marker:
    """One marker's fields (what the twin uses of visualization_msgs/Marker)."""

    def __init__(self, ns: str, mid: int, mtype: int, *, pose=(0.0, 0.0, 0.0, 0.0),
                 scale=(1.0, 1.0, 1.0), colour=(1.0, 1.0, 1.0, 1.0),
                 points: np.ndarray = None) -> None:
        self.ns, self.id, self.type = ns, mid, mtype
        self.pose, self.scale, self.colour = pose, scale, colour
        self.points = np.zeros((0, 3)) if points is None else points


def _write_marker(b: CdrBuilder, m: _Marker, stamp_ns: int, frame_id: str) -> None:
    b.stamp(stamp_ns)
    b.string(frame_id)
    b.string(m.ns)
    b.align(4)
    b.buf.extend(struct.pack('<iii', m.id, m.type, 0))
    x, y, z, yaw = m.pose
    for value in (x, y, z, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)):
        b.f64(value)
    for value in m.scale:
        b.f64(value)
    b.align(4)
    b.buf.extend(_F32x4.pack(*m.colour))
    b.buf.extend(struct.pack('<iI', 0, 0))  # lifetime 0: forever
    b.boolean(False)                       # frame_locked
    n = len(m.points)
    b.u32(n)
    if n:
        b.align(8)
        b.buf.extend(np.ascontiguousarray(m.points, dtype='<f8').tobytes())
    b.u32(0)                  # colors
    b.string('')              # texture_resource
    b.stamp(0)                # texture.header
    b.string('')
    b.string('')              # texture.format
    b.u32(0)                  # texture.data
    b.u32(0)                  # uv_coordinates
    b.string('')              # text
    b.string('')              # mesh_resource
    b.string('')              # mesh_file.filename
    b.u32(0)                  # mesh_file.data
    b.boolean(False)          # mesh_use_embedded_materials


def _marker_tail() -> bytes:
    """Return the fields after ``points`` (all empty), written from a 4-aligned offset (where
    the points always end: 24-byte points after 8-alignment, or the count alone)."""
    b = CdrBuilder()
    b.u32(0)                  # colors
    b.string('')              # texture_resource
    b.stamp(0)                # texture.header
    b.string('')
    b.string('')              # texture.format
    b.u32(0)                  # texture.data
    b.u32(0)                  # uv_coordinates
    b.string('')              # text
    b.string('')              # mesh_resource
    b.string('')              # mesh_file.filename
    b.u32(0)                  # mesh_file.data
    b.boolean(False)          # mesh_use_embedded_materials
    return bytes(b.buf)


_TAIL = _marker_tail()


def _append_marker(buf: bytearray, m: _Marker, stamp: bytes, frame_body: bytes) -> None:
    """Append one marker to a MarkerArray payload: the bytes of :func:`_write_marker`, with
    one call per group of fields (offsets relative to the payload start, ``len(buf)``).

    :param stamp: the packed ``builtin_interfaces/Time``.
    :param frame_body: the CDR string body of the frame id (unaligned).
    """
    buf += _ZEROS[-len(buf) & 3]
    buf += stamp
    buf += frame_body
    buf += _ZEROS[-len(buf) & 3]
    buf += string_bytes(m.ns)
    buf += _ZEROS[-len(buf) & 3]
    buf += _IDS.pack(m.id, m.type, 0)
    buf += _ZEROS[-len(buf) & 7]
    x, y, z, yaw = m.pose
    sx, sy, sz = m.scale
    buf += _POSE_SCALE.pack(x, y, z, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2), sx, sy,
                            sz)
    buf += _F32x4.pack(*m.colour)  # 8-aligned here
    buf += _LIFETIME_LOCKED         # lifetime 0 (forever), frame_locked false
    n = len(m.points)
    buf += _ZEROS[-len(buf) & 3]
    buf += _U32.pack(n)
    if n:
        buf += _ZEROS[-len(buf) & 7]
        buf += np.ascontiguousarray(m.points, dtype='<f8').tobytes()
    buf += _TAIL


def _static_prefix(markers: Sequence[_Marker], frame_id: str) -> bytes:
    """Return the payload of a MarkerArray's first markers, stamped 0 ("latest")."""
    b = CdrBuilder()
    b.u32(len(markers))
    for marker in markers:
        _write_marker(b, marker, 0, frame_id)
    return bytes(b.buf)


def arc_segments(radius: float, sweep: float, chord_error: float = CHORD_ERROR) -> int:
    """Return how many chords keep an arc of ``radius`` [m] over ``sweep`` [rad] within
    ``chord_error`` [m] of the circle."""
    step = 2.0 * math.acos(max(-1.0, 1.0 - chord_error / radius))
    return max(1, math.ceil(abs(sweep) / step))


def sector_triangles(curve, z: float) -> np.ndarray:
    """Return the (6 n, 3) vertices [m] of a curved belt's annular sector as triangles at
    height ``z``: two per chord of the outer arc (within :data:`CHORD_ERROR`)."""
    n = arc_segments(curve.outer_radius, curve.sweep)
    theta = curve.start_angle + curve.sweep * np.arange(n + 1) / n
    c, s = np.cos(theta), np.sin(theta)
    cx, cy = curve.centre
    inner = np.stack([cx + curve.inner_radius * c, cy + curve.inner_radius * s], 1)
    outer = np.stack([cx + curve.outer_radius * c, cy + curve.outer_radius * s], 1)
    quads = np.stack([inner[:-1], outer[:-1], outer[1:], inner[:-1], outer[1:], inner[1:]], 1)
    out = np.empty((6 * n, 3))
    out[:, :2] = quads.reshape(-1, 2)
    out[:, 2] = z
    return out


def _polyline_points(points: Sequence[Tuple[float, float]], z: float) -> np.ndarray:
    return np.array([(x, y, z) for x, y in points], dtype=np.float64)


class CellMarkers:
    """Markers of a cell's fixed geometry plus its moving parts and actuators."""

    def __init__(self, cell: Cell) -> None:
        self.cell = cell
        self.frame_id = cell.settings.frame_id
        static: List[_Marker] = []
        for i, belt in enumerate(cell.belts):
            if belt.curve is not None:
                static.append(_Marker('belts', i, TRIANGLE_LIST,
                                      points=sector_triangles(belt.curve, -0.005),
                                      colour=BELT_COLOUR))
                continue
            cx = 0.5 * (belt.start[0] + belt.end[0])
            cy = 0.5 * (belt.start[1] + belt.end[1])
            static.append(_Marker('belts', i, CUBE, pose=(cx, cy, -0.005, belt.angle),
                                  scale=(belt.length, belt.width, 0.01), colour=BELT_COLOUR))
        for i, obstacle in enumerate(cell.obstacles):
            if obstacle.kind == 'peg':
                (x, y), = obstacle.points
                d = 2 * obstacle.radius
                static.append(_Marker('obstacles', i, CYLINDER, pose=(x, y, 0.02, 0.0),
                                      scale=(d, d, 0.04), colour=OBSTACLE_COLOUR))
                continue
            pts = list(obstacle.points)
            if obstacle.kind == 'polygon':
                pts.append(pts[0])
            width = obstacle.thickness if obstacle.thickness > 0 else 0.005
            static.append(_Marker('obstacles', i, LINE_STRIP, scale=(width, 0.0, 0.0),
                                  points=_polyline_points(pts, 0.02), colour=OBSTACLE_COLOUR))
        # fixed geometry is stamped 0 ("use the latest transform") and encoded once
        self._static_count = len(static)
        self._static = _static_prefix(static, self.frame_id)
        self._frame_body = string_bytes(self.frame_id)
        self._beams = [_polyline_points([barrier.start, barrier.end], barrier.height)
                       for barrier in cell.light_barriers]

    def build(self, stamp_ns: int, part_type: np.ndarray, x: np.ndarray, y: np.ndarray,
              barrier_blocked: np.ndarray, actuator_position: np.ndarray) -> bytes:
        """Return the MarkerArray CDR for the current state.

        :param part_type: part type index per part; ``x``, ``y`` positions [m].
        :param barrier_blocked: blocked flag per light barrier.
        :param actuator_position: position per actuator [m or rad].
        """
        markers: List[_Marker] = []
        for index, pt in enumerate(self.cell.part_types):
            mask = part_type == index
            pts = np.empty((int(np.count_nonzero(mask)), 3))
            pts[:, 0], pts[:, 1], pts[:, 2] = x[mask], y[mask], 0.5 * pt.height
            if pt.shape == 'disc':
                scale, kind = (2 * pt.radius, 2 * pt.radius, pt.height), SPHERE_LIST
            else:
                scale, kind = (pt.length, pt.width, pt.height), CUBE_LIST
            markers.append(_Marker(f'parts/{pt.name}', index, kind, scale=scale, points=pts,
                                   colour=PART_COLOURS[index % len(PART_COLOURS)]))
        for i, beam in enumerate(self._beams):
            colour = BEAM_BLOCKED if i < len(barrier_blocked) and barrier_blocked[i] else BEAM_FREE
            markers.append(_Marker('light_barriers', i, LINE_LIST, scale=(0.003, 0.0, 0.0),
                                   points=beam, colour=colour))
        for i, act in enumerate(self.cell.actuators):
            markers.append(self._actuator(i, act, float(actuator_position[i])))
        buf = bytearray(self._static)
        struct.pack_into('<I', buf, 0, self._static_count + len(markers))
        stamp, frame_body = _STAMP.pack(*stamp_parts(stamp_ns)), self._frame_body
        for marker in markers:
            _append_marker(buf, marker, stamp, frame_body)
        return ENCAPSULATION_LE + bytes(buf)

    @staticmethod
    def _actuator(i: int, act, position: float) -> _Marker:
        heading = math.atan2(act.axis[1], act.axis[0])
        if act.kind == 'pusher':
            x = act.base[0] + position * act.axis[0]
            y = act.base[1] + position * act.axis[1]
            return _Marker('actuators', i, CUBE, pose=(x, y, 0.02, heading),
                           scale=(act.length, act.width, 0.04), colour=ACTUATOR_COLOUR)
        if act.kind in ('stopper', 'transfer'):
            height = max(position, 1e-4)
            colour = ACTUATOR_COLOUR
            if act.kind == 'transfer':
                colour = TRANSFER_UP if position >= act.engage_height else TRANSFER_DOWN
            return _Marker('actuators', i, CUBE, pose=(act.base[0], act.base[1],
                                                       0.5 * height, heading),
                           scale=(act.length, act.width, height), colour=colour)
        angle = heading + position
        x = act.base[0] + 0.5 * act.length * math.cos(angle)
        y = act.base[1] + 0.5 * act.length * math.sin(angle)
        return _Marker('actuators', i, CUBE, pose=(x, y, 0.02, angle),
                       scale=(act.length, act.width, 0.04), colour=ACTUATOR_COLOUR)
