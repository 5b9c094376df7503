"""Place the name labels of a cell drawing so that none overlaps another or the axes' ticks.

Each label is an annotation of a point of the cell (its anchor) with a preferred direction.
:func:`place_labels` tries, label by label, positions on rings of growing distance around the
anchor (the preferred direction first) and keeps the cheapest one that lies inside the axes and
overlaps no label placed before it; covering another label's anchor or a thin element (a
beam, a wall), or a leader line crossing a label or another leader, costs extra. A label away
from its anchor gets a leader line. Distances are in display pixels of the figure's renderer.
"""

import math
import weakref
from typing import List, Optional, Sequence, Tuple

#: gid of the annotations that :func:`place_labels` places.
LABEL_GID = 'cell-label'
#: Free space kept around a label [px at 72 dpi; scaled with the figure's dpi].
GAP = 2.0
#: Distances from the anchor tried, nearest first [points].
DISTANCES = (4.0, 10.0, 16.0, 24.0, 34.0, 46.0, 60.0, 78.0, 100.0, 130.0, 170.0)
_ANGLES = tuple(k * math.pi / 8 for k in range(16))

_prefs: 'weakref.WeakKeyDictionary' = weakref.WeakKeyDictionary()

Box = Tuple[float, float, float, float]  # x0, y0, x1, y1 [px]


def add_label(ax, x: float, y: float, text: str, colour: str, *,
              direction: Tuple[float, float] = (0.0, -1.0), fontsize: float = 7.0):
    """Add a label of the point (x, y) [m] to be placed by :func:`place_labels`.

    :param direction: preferred side of the anchor, a vector in display orientation.
    :return: the annotation (at its anchor until placed).
    """
    ann = ax.annotate(text, (x, y), xytext=(0, 0), textcoords='offset points',
                      fontsize=fontsize, color=colour, ha='center', va='center', zorder=9,
                      bbox=dict(boxstyle='round,pad=0.15', fc='white', ec='none', alpha=0.8),
                      arrowprops=dict(arrowstyle='-', color=colour, lw=0.6, shrinkA=0,
                                      shrinkB=0))
    ann.set_gid(LABEL_GID)
    ann.set_in_layout(False)
    norm = math.hypot(*direction) or 1.0
    _prefs[ann] = (direction[0] / norm, direction[1] / norm)
    return ann


def labels_of(ax) -> list:
    """Return the cell labels of ``ax`` (annotations added by :func:`add_label`)."""
    return [t for t in ax.texts if t.get_gid() == LABEL_GID]


def _box(bbox, pad: float = 0.0) -> Box:
    return bbox.x0 - pad, bbox.y0 - pad, bbox.x1 + pad, bbox.y1 + pad


def _overlap(a: Box, b: Box) -> float:
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    return w * h if w > 0 and h > 0 else 0.0


def _inside(a: Box, outer: Box) -> bool:
    return a[0] >= outer[0] and a[1] >= outer[1] and a[2] <= outer[2] and a[3] <= outer[3]


def shown_tick_labels(ax) -> list:
    """Return the tick labels of ``ax`` that are drawn (their tick within the view)."""
    shown = []
    for axis in (ax.xaxis, ax.yaxis):
        low, high = sorted(axis.get_view_interval())
        span = 1e-9 * max(abs(low), abs(high), 1.0)
        for tick in axis.get_major_ticks():
            label = tick.label1
            if (low - span <= tick.get_loc() <= high + span and label.get_visible()
                    and label.get_text()):
                shown.append(label)
    return shown


def tick_label_boxes(ax, renderer) -> List[Box]:
    """Return the boxes [px] of the shown tick labels, axis labels and title of ``ax``."""
    boxes = []
    texts = shown_tick_labels(ax) + [ax.xaxis.label, ax.yaxis.label, ax.title]
    for text in texts:
        if text.get_visible() and text.get_text():
            boxes.append(_box(text.get_window_extent(renderer)))
    return boxes


def _anchor_box(ax, label, scale: float) -> Box:
    x, y = ax.transData.transform(label.xy)
    r = 3.0 * scale
    return x - r, y - r, x + r, y + r


def _thin_elements(ax, renderer, labels: Sequence, scale: float) -> List[Box]:
    """Boxes [px] a label should not cover: beams, thin walls, the labels' anchors."""
    boxes = []
    for artist in list(ax.lines) + list(ax.patches):
        bb = artist.get_window_extent(renderer)
        if min(bb.width, bb.height) < 4.0 * scale:
            boxes.append(_box(bb, 1.0))
    return boxes + [_anchor_box(ax, label, scale) for label in labels]


def _cross(a, b, c, d) -> bool:
    """Return True if segment a-b crosses segment c-d (points in px)."""
    def side(p, q, r) -> float:
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])
    return (side(a, b, c) * side(a, b, d) < 0.0) and (side(c, d, a) * side(c, d, b) < 0.0)


def _segment_hits_box(a, b, box: Box) -> bool:
    """Return True if segment a-b enters ``box`` (px)."""
    x0, y0, x1, y1 = box
    if any(x0 <= p[0] <= x1 and y0 <= p[1] <= y1 for p in (a, b)):
        return True
    corners = ((x0, y0), (x1, y0), (x1, y1), (x0, y1))
    return any(_cross(a, b, corners[k], corners[(k + 1) % 4]) for k in range(4))


def _candidates(anchor: Tuple[float, float], size: Tuple[float, float],
                pref: Tuple[float, float], scale: float):
    """Yield (distance, cost, centre) of positions around ``anchor`` for a box of ``size``.

    Pixels; by growing distance, the cost adds a turn away from the preferred direction.
    """
    dx0, dy0 = pref
    w, h = size
    for dist in DISTANCES:
        r = dist * scale
        for angle in _ANGLES:
            dx, dy = math.cos(angle), math.sin(angle)
            turn = math.acos(max(-1.0, min(1.0, dx * dx0 + dy * dy0)))  # [rad] off preferred
            # the box's near side sits ``r`` from the anchor, along (dx, dy)
            cx = anchor[0] + dx * r + (0.5 * w if dx > 0.3 else -0.5 * w if dx < -0.3 else 0.0)
            cy = anchor[1] + dy * r + (0.5 * h if dy > 0.3 else -0.5 * h if dy < -0.3 else 0.0)
            yield r, r + 12.0 * scale * turn, (cx, cy)


def place_labels(ax, labels: Optional[Sequence] = None) -> List[Box]:
    """Move every cell label of ``ax`` to a free place; return their boxes [px].

    Call after the figure's layout is final (limits, aspect, ``tight_layout``): the figure is
    drawn once to measure the texts.
    """
    fig = ax.figure
    labels = labels_of(ax) if labels is None else list(labels)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    scale = fig.dpi / 72.0
    gap = GAP * scale
    area = _box(ax.get_window_extent(renderer), -gap)
    blocked = tick_label_boxes(ax, renderer)
    thin = _thin_elements(ax, renderer, labels, scale)
    taken: List[Box] = []
    leaders: List[Tuple[Tuple[float, float], Tuple[float, float]]] = []
    for label in labels:
        bb = label.get_bbox_patch().get_window_extent(renderer) \
            if label.get_bbox_patch() is not None else label.get_window_extent(renderer)
        text_bb = label.get_window_extent(renderer)
        size = (max(bb.width, text_bb.width), max(bb.height, text_bb.height))
        anchor = tuple(ax.transData.transform(label.xy))
        own = _anchor_box(ax, label, scale)
        best, best_cost = None, math.inf
        fallback, fallback_cost = None, math.inf
        for r, cost, (cx, cy) in _candidates(anchor, size,
                                             _prefs.get(label, (0.0, -1.0)), scale):
            if r >= best_cost:
                break
            if cost >= best_cost:
                continue
            box = (cx - size[0] / 2, cy - size[1] / 2, cx + size[0] / 2, cy + size[1] / 2)
            padded = (box[0] - gap, box[1] - gap, box[2] + gap, box[3] + gap)
            clash = sum(_overlap(padded, other) for other in taken + blocked)
            if not _inside(box, area):
                clash += 1e6
            penalty = sum(30.0 * scale for other in thin
                          if other != own and _overlap(box, other) > 0.0)
            if penalty + cost < best_cost and r > 0.5 * min(size):   # its leader line
                penalty += sum(40.0 * scale for other in taken
                               if _segment_hits_box(anchor, (cx, cy), other))
                penalty += sum(40.0 * scale for a, b in leaders if _cross(anchor, (cx, cy), a, b))
            if clash > 0.0:
                if clash + cost < fallback_cost:
                    fallback, fallback_cost = box, clash + cost
                continue
            if cost + penalty < best_cost:
                best, best_cost = box, cost + penalty
        box = best if best is not None else fallback
        cx, cy = 0.5 * (box[0] + box[2]), 0.5 * (box[1] + box[3])
        label.xyann = ((cx - anchor[0]) / scale, (cy - anchor[1]) / scale)  # [points]
        if math.hypot(cx - anchor[0], cy - anchor[1]) < 0.5 * min(size) + 1.0:
            label.arrow_patch.set_visible(False)
        else:
            leaders.append((anchor, (cx, cy)))
        taken.append(box)
    return taken
