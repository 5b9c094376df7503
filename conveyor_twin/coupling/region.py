"""One macro grid of the hand-over: its active mask, accumulators, sinks and type FIFO.

:class:`Region` holds what :class:`~conveyor_twin.coupling.scale.ScaleCoupling` keeps per macro
grid between steps (the steps themselves are in :mod:`.scale`): the ``active`` cell mask (all
cells for ``macro`` zones, the cells of macro tiles for ``auto`` zones), the boundary face
accumulators and their release phases, the sink cells and faces, the cells of a
``parts_vanish`` fault, and the FIFO of the types of the parts it holds.
"""

import math
from typing import Dict, Optional

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.coupling import handover as _ho
from conveyor_twin.coupling.tiles import AutoTiles, fill_cell_mask
from conveyor_twin.macro.solver import MacroSim

# Most positions tried for one released part (a lattice of part diameters over one cell
# around the window's mass centre, nearest first; the first one tried rotates).
MAX_OFFSETS = 49
# Clearance [m] between a released part and the face it crosses.
CLEARANCE = 1e-4


class Region:
    """One macro grid with its active mask, accumulators and sinks."""

    def __init__(self, cell: Cell, sim: MacroSim, radius: float) -> None:
        self.sim = sim
        g = sim.grid
        self.tiles: Optional[AutoTiles] = None
        # cells of sensor windows: no density flows into them (see handover.hold_back)
        self.closed = np.zeros((g.ny, g.nx), dtype=np.uint8)
        if sim.zone.policy == 'auto':
            self.tiles = AutoTiles(cell, sim.zone, g)
            self.active = self.tiles.cell_mask()
            fill_cell_mask(self.tiles.locked, self.tiles.tc, self.closed)
        else:
            self.active = np.ones((g.ny, g.nx), dtype=np.uint8)
        scratch = np.zeros((g.ny * g.nx, 2), dtype=np.int64)
        self.border = scratch[:_ho.border_cells(self.closed, scratch)].copy()
        self.face_ranges = [np.array([[0, g.ny, 0, 1]]), np.array([[0, g.ny, 0, 1]]),
                            np.array([[0, 1, 0, g.nx]]), np.array([[0, 1, 0, g.nx]])]
        # scratch of the micro-tile blocks (one per tile at most) and the inactive row runs
        n_tiles = self.tiles.macro.size if self.tiles is not None else 0
        self.blocks = np.zeros((n_tiles, 4), dtype=np.int64)
        self.runs = np.zeros((g.ny * ((g.nx + 1) // 2) if self.tiles is not None else 0, 3),
                             dtype=np.int64)
        self.n_runs = 0
        # cells where no released part may go: the active ones, and on a grid with curved
        # belts the cells off every belt or solid (a spot of the release lattice could
        # otherwise land behind a curve's guide rail)
        self.off_surface: Optional[np.ndarray] = None
        if any(b.curve is not None for b in cell.belts):
            self.off_surface = ((sim.belt_index < 0) | (sim.solid != 0)).astype(np.uint8)
        self.spot_refused = self.active
        # the same for the releases from the density of micro tiles, padded with refused cells
        # as far as the release lattice reaches beyond the grid (there no belt of the grid
        # holds a spot); None on a grid without curved belts (the unpadded mask is used)
        self.inner_refused: Optional[np.ndarray] = None
        self.inner_pad = 0
        self.update_ranges()
        # boundary faces, in the grid's boundary-face order (outflow): views of one array,
        # left/right (ny, 1), bottom/top (1, nx)
        ny, nx = g.ny, g.nx
        self.acc_flat = np.zeros(2 * (ny + nx))
        self.face_acc = [self.acc_flat[:ny].reshape(ny, 1),
                         self.acc_flat[ny:2 * ny].reshape(ny, 1),
                         self.acc_flat[2 * ny:2 * ny + nx].reshape(1, nx),
                         self.acc_flat[2 * ny + nx:].reshape(1, nx)]
        self.acc_max = np.zeros(4)
        self.face_skip = [np.zeros(a.shape, dtype=np.uint8) for a in self.face_acc]
        self.occ = np.zeros((g.ny, g.nx))
        self.w = max(1, int(math.ceil(radius / g.h)))
        # depth [cells] of the sensor windows' entrances (density from a macro tile waits there)
        self.entrance = _ho.entrance_depth(self.w, sim.rho_max, g.h)
        self.windows = (self.closed, self.entrance)  # as the hold-back takes them
        # spots over the whole window, so parts can leave side by side at the part spacing
        self.offsets = lattice((self.w + 0.5) * g.h, 2.0 * radius + CLEARANCE)
        self.rot = np.zeros(1, dtype=np.int64)
        self.grid_box = np.array([g.origin_x, g.origin_y, g.h])
        self.inner_box = self.grid_box
        if self.off_surface is not None:
            reach = float(np.abs(self.offsets).max()) * (2.0 * radius + CLEARANCE)
            pad = self.inner_pad = int(math.ceil(reach / g.h)) + self.w + 2
            self.inner_refused = np.ones((g.ny + 2 * pad, g.nx + 2 * pad), dtype=np.uint8)
            self.inner_box = np.array([g.origin_x - pad * g.h, g.origin_y - pad * g.h, g.h])
            self._pad_inner()
        # FIFO of the types of the parts deposited: (head, count, untyped releases)
        self.fifo = np.zeros(1024, dtype=np.int64)
        self.fstate = np.zeros(3, dtype=np.int64)
        self.sink_popped = 0  # whole parts of the sink outflow given a type
        self.left = 0.0  # mass that left through sinks in this grid [parts]
        # fault ``parts_vanish``: fault id -> flat indices of the cells whose mass falls off
        self.vanish: Dict[int, np.ndarray] = {}
        self.vanished = 0.0  # mass that fell off in this grid [parts]
        self.vanish_popped = 0  # whole parts of it given a type
        # arrival phases of the release windows (see handover.release_windows)
        self.rng = np.zeros(2)
        self.face_thr = [np.zeros(a.shape) for a in self.face_acc]
        self.thr = np.zeros((g.ny, g.nx))  # inside auto zones: no spread (see :mod:`.scale`)
        self.rng_inner = np.zeros(2)

        centres, normals = g.boundary_faces()
        self.face_centres, self.face_normals = centres, normals
        xc, yc = g.centres()
        self.sink_cells = np.zeros((g.ny, g.nx), dtype=np.bool_)
        face_out = centres + normals * radius
        self.face_sink = np.zeros(g.n_boundary, dtype=np.bool_)
        for sink in cell.sinks:
            x0, y0, x1, y1 = sink.region
            self.sink_cells |= (xc >= x0) & (xc <= x1) & (yc >= y0) & (yc <= y1)
            self.face_sink |= ((face_out[:, 0] >= x0) & (face_out[:, 0] <= x1)
                               & (face_out[:, 1] >= y0) & (face_out[:, 1] <= y1))
        self.has_sink_cells = bool(self.sink_cells.any())
        self.sink_index = np.flatnonzero(self.sink_cells).astype(np.int64)
        self.sides = [(0, ny), (ny, 2 * ny), (2 * ny, 2 * ny + nx), (2 * ny + nx, 2 * (ny + nx))]
        self.side_array = np.array(self.sides, dtype=np.int64)

    def cells_in(self, x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
        """Return the flat indices (ascending) of the cells whose centre lies in a rectangle."""
        xc, yc = self.sim.grid.centres()
        inside = (xc >= x0) & (xc <= x1) & (yc >= y0) & (yc <= y1)
        return np.flatnonzero(inside).astype(np.int64)

    def seed_phases(self, spread: float, state: int) -> None:
        """Draw every window's first arrival phase (``spread * u`` [parts], ``u`` uniform
        from NumPy's PCG64 seeded with ``state``); later draws use the kernel's generator."""
        self.rng[0] = spread
        self.rng[1] = float(state % (1 << 48))
        gen = np.random.default_rng(state)
        for arr in self.face_thr:
            arr[...] = spread * gen.random(arr.shape) if spread > 0.0 else 0.0

    def update_ranges(self) -> None:
        """List the cell blocks of the micro tiles (where released mass can wait), merged
        where the scan order is kept (:func:`~conveyor_twin.coupling.handover.micro_blocks`),
        and the row runs of the inactive cells (:func:`~.handover.inactive_runs`)."""
        t = self.tiles
        if t is None:
            self.ranges = np.zeros((0, 4), dtype=np.int64)
            return
        g = self.sim.grid
        m = _ho.micro_blocks(t.macro, t.tc, g.ny, g.nx, self.blocks)
        self.ranges = self.blocks[:m]
        self.n_runs = _ho.inactive_runs(self.active, self.runs)
        if self.off_surface is not None:
            self.spot_refused = self.active | self.off_surface
            self._pad_inner()

    def _pad_inner(self) -> None:
        if self.inner_refused is not None:
            p = self.inner_pad
            self.inner_refused[p:-p, p:-p] = self.spot_refused

    def inactive_mass(self) -> float:
        """Mass in the cells of micro tiles (flowing on, released as whole parts) [parts]."""
        if self.tiles is None:
            return 0.0
        rho = self.sim.density
        return float(rho[self.active == 0].sum()) * self.sim.grid.h ** 2

    def pending(self) -> float:
        """Mass waiting to be released as whole parts [parts]: the boundary accumulators and
        the density in the cells of micro tiles."""
        return self.inactive_mass() + sum(float(a.sum()) for a in self.face_acc)

    def reserve_types(self, k: int) -> None:
        """Grow the FIFO's ring buffer so ``k`` more types fit."""
        head, count = int(self.fstate[0]), int(self.fstate[1])
        size = self.fifo.size
        if count + k > size:
            new = np.zeros(max(2 * size, count + k), dtype=np.int64)
            new[:count] = np.roll(self.fifo, -head)[:count]
            self.fifo = new
            self.fstate[0] = 0

    def pop_types(self, k: int) -> np.ndarray:
        """Remove and return the ``k`` oldest types (type 0 for missing ones)."""
        head, count = int(self.fstate[0]), int(self.fstate[1])
        take = min(k, count)
        out = self.fifo[(head + np.arange(take)) % self.fifo.size].copy()
        self.fstate[0] = (head + take) % self.fifo.size
        self.fstate[1] = count - take
        if take < k:
            self.fstate[2] += k - take
            out = np.concatenate([out, np.zeros(k - take, dtype=np.int64)])
        return out

    def types_held(self, n_types: int) -> np.ndarray:
        """Return the parts per type in the FIFO (deposited, not yet released or sunk)."""
        head, count = int(self.fstate[0]), int(self.fstate[1])
        held = self.fifo[(head + np.arange(count)) % self.fifo.size]
        return np.bincount(held, minlength=n_types)[:n_types]



def lattice(half: float, d: float) -> np.ndarray:
    """Return ``(k, 2)`` lattice offsets [diameters] within ``half`` [m], nearest first."""
    n = max(1, int(half / d + 1e-9))
    a = np.arange(-n, n + 1, dtype=np.float64)
    pts = np.stack(np.meshgrid(a, a), axis=-1).reshape(-1, 2)
    order = np.lexsort((pts[:, 1], pts[:, 0], np.hypot(pts[:, 0], pts[:, 1])))
    return np.ascontiguousarray(pts[order][:MAX_OFFSETS])
