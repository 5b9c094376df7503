"""MacroSim: the macro-scale material-flow PDE of one zone, stepped at the twin's step.

``d rho/dt + div(rho (v(x) + I(rho))) = 0`` (docs/models.md) with ``rho`` in parts/m^2, solved
by dimensional splitting with 1D finite-volume sweeps (:mod:`conveyor_twin.macro.fluxes`), either
with the capped flux of Hoher et al. (``capped``: no operator, receiver capacity cut) or with the
collision operator of Göttlich et al. (``goettlich``: :mod:`conveyor_twin.macro.collision`).
Papers: S. Hoher et al., *System Dynamic Models and Real-time Simulation of Complex Material
Flow Systems*; S. Göttlich et al., *Modeling, simulation and validation of material flow on
conveyor belts* (Appl. Math. Modelling, 2014).

Time stepping: one call ``step(n)`` advances ``n`` twin steps of ``cell.settings.step`` seconds,
each split into ``nsub`` equal substeps with ``nsub = ceil(dt * s / (h * cfl))``; ``s`` is the
largest per-cell outflow speed of a sweep (the sum of a cell's outgoing face speeds, so the
first-order sweep is positive), plus ``2 eps`` for the operator. Consecutive substeps alternate
the sweep order (x then y, y then x), which makes the splitting second order over pairs.
Everything inside ``step`` runs in one compiled call on preallocated arrays.

Boundaries (faces ordered left(iy), right(iy), bottom(ix), top(ix); see
:meth:`conveyor_twin.macro.grid.Grid.boundary_faces`): where the face velocity leaves the grid
the donor cell's content leaves (upwind), and is added to :attr:`MacroSim.outflow` for that
face; elsewhere a prescribed inflow rate [parts/s] per face (:meth:`MacroSim.set_inflow`) enters,
cut by the free capacity of the receiving cell in the capped variant; what entered is in
:attr:`MacroSim.inflow`. The coordinator keeps what was refused.

Parameters (cell ``macro`` section; the values here are what the embedded cell gives):

- ``rho_max``: 0 derives hexagonal packing of the first part type's footprint disc,
  ``1 / (2 sqrt(3) R^2)`` = 11547 /m^2 for the default cell's 10 mm spacers (a close-packed jam of
  standing discs; the densest planar arrangement, 0.907 of the area covered).
- ``epsilon`` (operator speed): it must exceed the largest belt speed, or the belt packs a
  jam faster than the operator can spread it; the cell default 0.5 m/s equals the rig's belt
  speed. Recommended default: the largest belt ``max_speed`` (2 m/s in the rig); the capacity
  guard keeps the bound either way.
- ``mollifier_width``: 0 means two cells (taps 0.23, 0.54, 0.23): the smallest kernel that
  smooths the cell-to-cell noise of the H switch, close to the spacer diameter on a 1 cm grid;
  wider kernels smear the push over several part diameters and cost ``(2 r + 1)`` per pass.
- ``scheme`` ``limited`` uses the MC limiter (:data:`DEFAULT_LIMITER`): observed order 2.0 on
  a smooth problem against 1.8 for minmod (``limiter=LIMITER_MINMOD`` selects it).
- ``slide_band`` (:data:`DEFAULT_SLIDE_BAND`, 5 cm): depth of the sliding layer in front of
  fixed obstacles; with one cell the jam in front of the rig's deflector passes 180 of
  500 parts/s through the gap, with 5 cm the inflow up to ~250-430 parts/s (capped/Göttlich).

Actuators: an engaged actuator is a solid region (a stopper from ``engage_height`` on, pushers
and diverter arms always); the faces of its sliding band carry its normal speed, so a pusher
drives the material in front of it at its own speed while the belt's tangential component stays.
Cells newly covered by a moving actuator are emptied by pushing their content ahead in the
direction of the actuator's motion (a stopper rising under material pushes it upstream against
the belt), filling cells up to ``rho_max``; what is pushed past the grid edge leaves through
that boundary face as outflow.
"""

import math
import struct
from typing import Optional, Sequence, Union

from numba import njit
import numpy as np

from conveyor_twin.cell.model import (Cell, MACRO_SCHEMES, MACRO_VARIANTS, MacroScheme,
                                      MacroVariant, Rect, Zone)
from conveyor_twin.macro import collision as _col
from conveyor_twin.macro import curves as _curves
from conveyor_twin.macro import fluxes as _fx
from conveyor_twin.macro import grid as _grid

DEFAULT_LIMITER = _fx.LIMITER_MC
# Depth [m] of the sliding layer in front of fixed obstacles (see MacroSim).
DEFAULT_SLIDE_BAND = 0.05
# How far (cells) a newly covered cell's content is pushed ahead before it is overfilled.
SWEEP_MAX_CELLS = 64
# Sub-samples per cell edge of the disc footprint in :meth:`MacroSim.deposit`.
DEPOSIT_SAMPLES = 8


@njit(cache=True)
def _merge_y_ranges(yr: np.ndarray, lohi: np.ndarray, out: np.ndarray) -> None:
    """Store in ``out`` the hull of the y-face ranges ``yr`` and the operator's y faces."""
    nf = yr.shape[0]
    ny = nf - 1
    for f in range(nf):
        lo = yr[f, 0]
        hi = yr[f, 1]
        if 0 < f < ny:
            a, b = _col._face_row_range(lohi, f, ny)
            if b > a:
                if hi > lo:
                    lo = min(lo, a)
                    hi = max(hi, b)
                else:
                    lo = a
                    hi = b
        out[f, 0] = lo
        out[f, 1] = hi


# numba keys the on-disk cache of ``advance`` on this file only, and ``advance`` compiles the
# kernels of fluxes.py and collision.py into itself: after editing those, change this file (or
# clear ``__pycache__``), or ``advance`` keeps running the old kernels from the cache.
@njit(cache=True)
def advance(nsteps: int, nsub: int, dts: float, field: tuple, scheme: tuple, boundary: tuple,
            work: tuple, collision: tuple) -> int:
    """Advance ``nsteps`` twin steps of ``nsub`` substeps of ``dts`` [s] each, in place.

    ``parity[0]`` counts substeps (the sweep order alternates with it). ``wx``, ``wy`` are the
    total face velocities (equal to the belt field ``ux``, ``uy`` except where the collision
    operator acts). ``in_acc``, ``out_acc`` are zeroed first and hold this call's boundary
    amounts [parts]; ``out_acc`` is then added to ``out_total``. ``yr``: y-face ranges of the
    belt field (:func:`conveyor_twin.macro.fluxes.y_ranges`); ``yr_op``: work of the same
    shape (merged with the operator's faces). Other arguments as in
    :func:`conveyor_twin.macro.fluxes.sweep_x` and
    :func:`conveyor_twin.macro.collision.collision_operator`. Return a bit mask: 1 if any
    ``in_acc`` entry is nonzero, 2 if any ``out_acc`` entry is.

    The arguments come in tuples by concept (unpacked here, no copies):

    :param field: ``(rho, ux, uy, wx, wy, solid)``: density [parts/m^2], belt and total face
        velocities [m/s], solid mask.
    :param scheme: ``(h, rho_max, capped, limited, limiter)``: cell edge [m], density cap
        [parts/m^2], capacity guard, second order, limiter id.
    :param boundary: ``(in_rate, in_acc, out_acc, out_total)`` per boundary face.
    :param work: ``(parity, ax, ay, slope, seed, yr, yr_op)``.
    :param collision: ``(use_op, eps, w, dx, dy, gx, gy, lohi, rng)``: the collision
        operator (used when ``use_op``), strength ``eps`` [m/s] and its work arrays.
    """
    rho, ux, uy, wx, wy, solid = field
    h, rho_max, capped, limited, limiter = scheme
    in_rate, in_acc, out_acc, out_total = boundary
    parity, ax, ay, slope, seed, yr, yr_op = work
    use_op, eps, w, dx, dy, gx, gy, lohi, rng = collision
    in_acc[:] = 0.0
    out_acc[:] = 0.0
    for _ in range(nsteps):
        for _q in range(nsub):
            yrs = yr
            if use_op:
                _col.collision_operator(field, rho_max, h, collision)
                _merge_y_ranges(yr, lohi, yr_op)
                yrs = yr_op
            if parity[0] % 2 == 0:
                _fx.sweep_x(rho, wx, solid, dts, h, rho_max, capped, limited, limiter,
                            in_rate, in_acc, out_acc, ax, slope, seed)
                _fx.sweep_y(rho, wy, solid, dts, h, rho_max, capped, limited, limiter,
                            in_rate, in_acc, out_acc, ay, yrs)
            else:
                _fx.sweep_y(rho, wy, solid, dts, h, rho_max, capped, limited, limiter,
                            in_rate, in_acc, out_acc, ay, yrs)
                _fx.sweep_x(rho, wx, solid, dts, h, rho_max, capped, limited, limiter,
                            in_rate, in_acc, out_acc, ax, slope, seed)
            parity[0] += 1
    flags = 0
    for i in range(out_acc.size):
        out_total[i] += out_acc[i]
        if out_acc[i] != 0.0:
            flags |= 2
    for i in range(in_acc.size):
        if in_acc[i] != 0.0:
            flags |= 1
    return flags


class MacroSim:
    """Density of one macro zone [parts/m^2] on a uniform grid, advanced by the macro PDE.

    :param cell: the validated cell.
    :param zone: the zone (object or name); None: the cell's first zone.
    :param variant: ``capped`` or ``goettlich``; None: ``cell.macro.variant``.
    :param scheme: ``upwind`` or ``limited``; None: ``cell.macro.scheme``.
    :param limiter: slope limiter of the ``limited`` scheme (``fluxes.LIMITER_*``).
    :param guard: ``goettlich`` only: also apply the receiver-capacity cut to the total flux
        ``rho (v + I)``, so ``rho <= rho_max`` holds to round-off. Without it the operator
        alone holds the density only approximately (measured up to 1.9 rho_max in a stopper
        queue, see the tests); ``capped`` always cuts.
    :param slide_band: depth [m] in front of fixed obstacles over which the velocity's normal
        component is removed (at least one cell): the jam in front of a deflector slides
        along it as a layer of this depth.
    """

    def __init__(self, cell: Cell, zone: Union[Zone, str, None] = None, *,
                 variant: Optional[str] = None, scheme: Optional[str] = None,
                 limiter: int = DEFAULT_LIMITER, guard: bool = True,
                 slide_band: float = DEFAULT_SLIDE_BAND) -> None:
        self.cell = cell
        self.zone = _grid.zone_for(cell, zone)
        variant = variant or cell.macro.variant
        scheme = scheme or cell.macro.scheme
        if variant not in MACRO_VARIANTS:
            msg = f'macro variant {str(variant)!r} is not one of {MACRO_VARIANTS}'
            raise ValueError(msg)
        if scheme not in MACRO_SCHEMES:
            msg = f'macro scheme {str(scheme)!r} is not one of {MACRO_SCHEMES}'
            raise ValueError(msg)
        self.variant = MacroVariant(variant)
        self.scheme = MacroScheme(scheme)
        self.limiter = int(limiter)
        self.capacity_guard = self.variant == MacroVariant.CAPPED or bool(guard)
        self.grid = g = _grid.Grid.from_zone(self.zone)
        self.dt = float(cell.settings.step)
        self.rho_max = float(cell.rho_max)
        self.epsilon = float(cell.macro.epsilon) if self.variant == MacroVariant.GOETTLICH else 0.0
        self.cfl = float(cell.macro.cfl)
        ny, nx = g.ny, g.nx
        self._rho = np.zeros((ny, nx))
        self._belt_idx = _grid.belt_index_of_cells(g, cell.belts)
        self._belt_dir = np.array([(0.0, 0.0) if b.curve is not None else b.direction
                                   for b in cell.belts], dtype=np.float64)
        self._belt_dir = self._belt_dir.reshape(len(cell.belts), 2)
        self._speeds = np.array([b.speed for b in cell.belts], dtype=np.float64)
        self._surfaces = _curves.Surfaces(g, cell, self._belt_idx, self._belt_dir, self._speeds)
        band_cells = max(1, int(round(slide_band / g.h)))
        obstacles, rails = _curves.split_rails(cell.belts, cell.obstacles)
        self._static_solid, self._normal_s = _grid.rasterise_static(g, obstacles, band_cells)
        if rails:
            xc, yc = g.centres()
            rail_solid = ((_grid.rasterise_static(g, rails, 1)[0] != 0)
                          | _curves.rail_cells(xc, yc, cell.belts, self._belt_idx))
            rail_solid &= self._belt_idx < 0
            self._static_solid |= rail_solid.astype(np.uint8)
        # Only actuators whose footprint can reach the grid matter.
        self._actuators = tuple(cell.actuators)
        self._positions = np.array([a.initial_position for a in cell.actuators], dtype=float)
        self._rates = np.zeros(len(cell.actuators))
        self._solid = self._static_solid.copy()
        self._normal_a = np.zeros((ny, nx, 2))
        self._wall_a = np.zeros((ny, nx))
        self._wall_vel = np.zeros((ny, nx, 2))
        self._vc = np.zeros((ny, nx, 2))
        self._ux = np.zeros((ny, nx + 1))
        self._uy = np.zeros((ny + 1, nx))
        self._wx = np.zeros((ny, nx + 1))
        self._wy = np.zeros((ny + 1, nx))
        self._ax = np.zeros((ny, nx + 1))
        self._ay = np.zeros((ny + 1, nx))
        self._slope = np.zeros((ny, nx))
        self._dx = np.zeros((ny, nx + 1))
        self._dy = np.zeros((ny + 1, nx))
        self._gx = np.zeros((ny, nx + 1))
        self._gy = np.zeros((ny + 1, nx))
        self._seed = np.zeros(max(nx, ny) + 1, dtype=np.uint8)
        self._yr = np.zeros((ny + 1, 2), dtype=np.int64)
        self._yr_op = np.zeros((ny + 1, 2), dtype=np.int64)
        self._use_op = self.variant == MacroVariant.GOETTLICH
        self._limited = self.scheme == MacroScheme.LIMITED
        self._lohi = np.zeros((ny, 2), dtype=np.int64)
        self._rng = np.zeros((ny, 2), dtype=np.int64)
        self._parity = np.zeros(1, dtype=np.int64)
        self._w = _col.mollifier_weights(g.h, cell.macro.mollifier_width)
        nb = g.n_boundary
        self._in_rate = np.zeros(nb)
        self.inflow = np.zeros(nb)
        self.outflow = np.zeros(nb)
        self._pending_out = np.zeros(nb)
        self._has_pending = False
        self.outflow_total = np.zeros(nb)
        self.parts_in = 0.0
        self.parts_out = 0.0
        self.parts_deposited = 0.0
        self.parts_taken = 0.0
        self.steps = 0
        self._smax = 0.0
        self.substeps = 1
        self._rasterise_actuators()
        self._rebuild()

    # --- geometry -------------------------------------------------------------------------

    @property
    def density(self) -> np.ndarray:
        """The density [parts/m^2], ``(ny, nx)`` row-major (index ``iy * nx + ix``), a view."""
        return self._rho

    @property
    def origin_x(self) -> float:
        """x of the grid's lower-left corner [m]."""
        return self.grid.origin_x

    @property
    def origin_y(self) -> float:
        """y of the grid's lower-left corner [m]."""
        return self.grid.origin_y

    @property
    def resolution(self) -> float:
        """Cell edge [m]."""
        return self.grid.h

    @property
    def nx(self) -> int:
        """Cells along x."""
        return self.grid.nx

    @property
    def ny(self) -> int:
        """Cells along y."""
        return self.grid.ny

    @property
    def solid(self) -> np.ndarray:
        """``(ny, nx)`` uint8, 1 where obstacles or engaged actuators make the cell solid."""
        return self._solid

    @property
    def belt_index(self) -> np.ndarray:
        """``(ny, nx)`` int32 index of the belt each cell belongs to, -1 for none (a view)."""
        return self._belt_idx

    @property
    def cell_velocity(self) -> np.ndarray:
        """``(ny, nx, 2)`` cell-centre velocity of the belt field [m/s] (without operator)."""
        return self._vc

    @property
    def face_velocity(self):
        """``(ux, uy)``: face velocities [m/s], ``(ny, nx + 1)`` and ``(ny + 1, nx)``."""
        return self._ux, self._uy

    @property
    def belt_speeds(self) -> np.ndarray:
        """Current belt speeds [m/s] (a copy)."""
        return self._speeds.copy()

    @property
    def actuator_positions(self) -> np.ndarray:
        """Current actuator positions [m or rad] (a copy)."""
        return self._positions.copy()

    # --- commands ---------------------------------------------------------------------------

    def set_belt_speeds(self, speeds: Sequence[float]) -> None:
        """Set every belt's speed [m/s] (cell order); the field is rebuilt only on change."""
        speeds = np.asarray(speeds, dtype=np.float64)
        if speeds.shape != self._speeds.shape:
            msg = f'expected {self._speeds.size} belt speeds, got shape {speeds.shape}'
            raise ValueError(msg)
        if speeds.tolist() == self._speeds.tolist():  # np.array_equal, without its overhead
            return
        self._speeds[:] = speeds
        self._surfaces.set_speeds(self._speeds)
        self._rebuild()

    def set_actuator_positions(self, positions: Sequence[float],
                               rates: Optional[Sequence[float]] = None) -> None:
        """Set every actuator's position [m or rad] (cell order).

        :param rates: their rates of change [m/s or rad/s]; None derives them from the change
            since the previous call over one twin step (the coordinator's per-step hand-over).
        """
        positions = np.asarray(positions, dtype=np.float64)
        if positions.shape != self._positions.shape:
            msg = f'expected {self._positions.size} actuator positions, got {positions.shape}'
            raise ValueError(msg)
        if rates is None:
            rates = (positions - self._positions) / self.dt
        rates = np.asarray(rates, dtype=np.float64)
        # np.array_equal (shapes checked above), without its overhead
        if positions.tolist() == self._positions.tolist() and (
                rates.shape == self._rates.shape and rates.tolist() == self._rates.tolist()):
            return
        self._positions[:] = positions
        self._rates[:] = rates
        old_solid = self._solid.copy()
        old_vc = self._vc.copy()
        self._rasterise_actuators()
        self._sweep_covered(old_solid, old_vc)
        self._rebuild()

    def set_inflow(self, rates: Sequence[float]) -> None:
        """Set the prescribed inflow per boundary face [parts/s].

        The order is that of :meth:`conveyor_twin.macro.grid.Grid.boundary_faces`.
        """
        rates = np.asarray(rates, dtype=np.float64)
        if rates.shape != self._in_rate.shape or np.any(rates < 0.0):
            msg = f'expected {self._in_rate.size} non-negative inflow rates, got {rates.shape}'
            raise ValueError(msg)
        self._in_rate[:] = rates

    # --- stepping ---------------------------------------------------------------------------

    def step(self, n: int = 1) -> None:
        """Advance ``n`` twin steps; :attr:`inflow` / :attr:`outflow` hold this call's amounts."""
        flags = advance(
            int(n), self.substeps, self.dt / self.substeps,
            (self._rho, self._ux, self._uy, self._wx, self._wy, self._solid),
            (self.grid.h, self.rho_max, self.capacity_guard, self._limited, self.limiter),
            (self._in_rate, self.inflow, self.outflow, self.outflow_total),
            (self._parity, self._ax, self._ay, self._slope, self._seed, self._yr, self._yr_op),
            (self._use_op, self.epsilon, self._w, self._dx, self._dy, self._gx, self._gy,
             self._lohi, self._rng))
        # all-zero amounts add nothing (the sums are skipped, not changed)
        if flags & 1:
            self.parts_in += float(self.inflow.sum())
        if flags & 2:
            self.parts_out += float(self.outflow.sum())
        if self._has_pending:
            # Actuator sweeps since the last call (already in parts_out / outflow_total).
            self.outflow += self._pending_out
            self._pending_out.fill(0.0)
            self._has_pending = False
        self.steps += int(n)

    def total_parts(self) -> float:
        """Return the integral of the density over the grid [parts]."""
        return float(self._rho.sum()) * self.grid.h * self.grid.h

    # --- mass exchange ----------------------------------------------------------------------

    def deposit(self, x: float, y: float, radius_or_kernel: Union[float, np.ndarray],
                amount: float = 1.0) -> None:
        """Add exactly ``amount`` parts spread over a footprint around ``(x, y)`` [m].

        :param radius_or_kernel: a disc radius [m] (weights = area of the disc in each cell,
            sub-sampled), or a 2D array of weights with odd shape centred on the cell holding
            ``(x, y)`` (rows along y). Weights on solid or outside cells are dropped and the rest
            renormalised, so exactly ``amount`` is added; if nothing is left the nearest fluid
            cell takes it all. The density may exceed ``rho_max`` where parts are dropped onto a
            full region; both variants relax it (the capped sweep refuses inflow to such cells).
        :raises ValueError: if ``(x, y)`` is outside the grid.
        """
        g = self.grid
        fx, fy = (x - g.origin_x) / g.h, (y - g.origin_y) / g.h
        if not (0.0 <= fx < g.nx and 0.0 <= fy < g.ny):
            msg = f'deposit at ({x:g}, {y:g}) m is outside the zone {self.zone.name!r}'
            raise ValueError(msg)
        ic, jc = int(fx), int(fy)
        if isinstance(radius_or_kernel, np.ndarray):
            kern = np.asarray(radius_or_kernel, dtype=np.float64)
            ky, kx = kern.shape
            if ky % 2 == 0 or kx % 2 == 0:
                raise ValueError('deposit kernel must have odd dimensions')
            j0, i0 = jc - ky // 2, ic - kx // 2
        else:
            radius = float(radius_or_kernel)
            r_cells = int(math.ceil(radius / g.h)) + 1
            j0, i0 = jc - r_cells, ic - r_cells
            n = 2 * r_cells + 1
            s = DEPOSIT_SAMPLES
            sub = (np.arange(s) + 0.5) / s
            cx = (i0 + np.arange(n)[:, None] + sub[None, :]).ravel() * g.h + g.origin_x
            cy = (j0 + np.arange(n)[:, None] + sub[None, :]).ravel() * g.h + g.origin_y
            inside = ((cx[None, :] - x) ** 2 + (cy[:, None] - y) ** 2) <= radius * radius
            kern = inside.reshape(n, s, n, s).sum(axis=(1, 3)).astype(np.float64)
        ky, kx = kern.shape
        jj0, jj1 = max(0, j0), min(g.ny, j0 + ky)
        ii0, ii1 = max(0, i0), min(g.nx, i0 + kx)
        wts = kern[jj0 - j0:jj1 - j0, ii0 - i0:ii1 - i0] * (
            self._solid[jj0:jj1, ii0:ii1] == 0)
        total = float(wts.sum())
        if total <= 0.0:
            jn, inn = self._nearest_fluid(jc, ic)
            self._rho[jn, inn] += amount / (g.h * g.h)
        else:
            self._rho[jj0:jj1, ii0:ii1] += (amount / (total * g.h * g.h)) * wts
        self.parts_deposited += float(amount)

    def region_parts(self, rect: Rect) -> float:
        """Return the parts in the cells whose centres lie in ``rect`` [m] (nothing removed)."""
        rows, cols = self.grid.cell_slices(rect)
        return float(self._rho[rows, cols].sum()) * self.grid.h ** 2

    def take_region(self, rect: Rect) -> float:
        """Remove and return the parts in the cells whose centres lie in ``rect`` [m]."""
        rows, cols = self.grid.cell_slices(rect)
        taken = float(self._rho[rows, cols].sum()) * self.grid.h ** 2
        self._rho[rows, cols] = 0.0
        self.parts_taken += taken
        return taken

    def balance_error(self, initial: float = 0.0) -> float:
        """Return ``total - (initial + in + deposited - out - taken)`` [parts] (round-off only)."""
        expected = (initial + self.parts_in + self.parts_deposited - self.parts_out
                    - self.parts_taken)
        return self.total_parts() - expected

    def state_bytes(self) -> bytes:
        """Return the full dynamic state as bytes (bit-identical runs give identical bytes)."""
        head = struct.pack('<q5d', self.steps, self.parts_in, self.parts_out,
                           self.parts_deposited, self.parts_taken, float(self._parity[0]))
        return b''.join([head, self._rho.tobytes(), self._speeds.tobytes(),
                         self._positions.tobytes(), self._rates.tobytes(),
                         self._in_rate.tobytes(), self.outflow_total.tobytes()])

    # --- internals --------------------------------------------------------------------------

    def _rasterise_actuators(self) -> None:
        solid_a, self._normal_a, self._wall_a, self._wall_vel = _grid.rasterise_actuators(
            self.grid, self._actuators, self._positions, self._rates, self._static_solid)
        self._solid = (self._static_solid | solid_a).astype(np.uint8)
        self._surfaces.place(self._positions)

    def _rebuild(self) -> None:
        """Rebuild the face velocities and the CFL substep count."""
        f = self._surfaces
        self._smax = _grid.build_velocity(f.idx, f.direction, f.speeds, self._solid,
                                          self._normal_s, self._normal_a, self._wall_a,
                                          self._vc, self._ux, self._uy, f.curve)
        np.copyto(self._wx, self._ux)
        np.copyto(self._wy, self._uy)
        _fx.y_ranges(self._uy, self._yr)
        self._rng.fill(0)
        speed = self._smax + 2.0 * self.epsilon
        self.substeps = max(1, int(math.ceil(self.dt * speed / (self.grid.h * self.cfl)
                                             - 1e-9)))

    def _nearest_fluid(self, j: int, i: int):
        fluid = np.argwhere(self._solid == 0)
        if fluid.size == 0:
            raise ValueError('the zone has no fluid cell')
        d = (fluid[:, 0] - j) ** 2 + (fluid[:, 1] - i) ** 2
        k = int(np.argmin(d))
        return int(fluid[k, 0]), int(fluid[k, 1])

    def _sweep_covered(self, old_solid: np.ndarray, old_vc: np.ndarray) -> None:
        """Push the content of cells newly covered by an actuator ahead of it (conservative)."""
        covered = (self._solid != 0) & (old_solid == 0) & (self._rho != 0.0)
        if not covered.any():
            return
        g = self.grid
        for j, i in np.argwhere(covered):
            vx, vy = self._wall_vel[j, i]
            if vx == 0.0 and vy == 0.0:
                vx, vy = -old_vc[j, i, 0], -old_vc[j, i, 1]
            m = self._rho[j, i]
            self._rho[j, i] = 0.0
            if vx == 0.0 and vy == 0.0:
                jn, inn = self._nearest_fluid(j, i)
                self._rho[jn, inn] += m
                continue
            if abs(vx) >= abs(vy):
                dj, di = 0, (1 if vx > 0.0 else -1)
            else:
                dj, di = (1 if vy > 0.0 else -1), 0
            jj, ii, last = j, i, None
            for _ in range(SWEEP_MAX_CELLS):
                jj, ii = jj + dj, ii + di
                if not (0 <= jj < g.ny and 0 <= ii < g.nx):
                    # Pushed over the grid edge: outflow through that boundary face.
                    if ii < 0:
                        face = jj
                    elif ii >= g.nx:
                        face = g.ny + jj
                    elif jj < 0:
                        face = 2 * g.ny + ii
                    else:
                        face = 2 * g.ny + g.nx + ii
                    amount = m * g.h * g.h
                    self._pending_out[face] += amount
                    self._has_pending = True
                    self.parts_out += amount
                    self.outflow_total[face] += amount
                    m = 0.0
                    break
                if self._solid[jj, ii] != 0:
                    continue
                last = (jj, ii)
                room = max(0.0, self.rho_max - self._rho[jj, ii])
                put = min(room, m)
                self._rho[jj, ii] += put
                m -= put
                if m <= 0.0:
                    break
            if m > 0.0:
                if last is None:
                    last = self._nearest_fluid(j, i)
                self._rho[last] += m
