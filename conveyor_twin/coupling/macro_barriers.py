"""Light barriers inside a macro region: edges from the density and its flux.

Model ("virtual part column"): the parts crossing the beam in a step are the upwind flux
``q = sum_rows rho_upwind u_n h dt`` [parts] over the beam's faces (``u_n`` the belt field's
speed normal to the beam). Their running sum ``C`` is the expected crossing count; each time it
passes an integer a virtual part of the zone's part type reaches the beam: a rising edge at the
interpolated time (linear within the step) unless the beam is still blocked. The beam clears
(falling edge) once the last virtual part has travelled its footprint length ``2 R`` at the
flux-weighted normal speed past the beam. So in sparse flow the edges are ``2 round(C)``; in
dense flow, where consecutive parts follow within ``2 R / u_n``, the beam stays blocked, and a
stopped queue on the beam keeps it blocked, as a real beam would. Edges carry part id 0.

Only beams along a grid axis (constant x or constant y) are modelled; the beam is snapped to the
nearest face line of the grid.
"""

from typing import List, Tuple

import numpy as np

from conveyor_twin.cell.model import LightBarrier
from conveyor_twin.macro.solver import MacroSim


class MacroBarrier:
    """State of one light barrier modelled on a macro grid.

    :param index: the barrier's index in the cell. :param barrier: the barrier.
    :param sim: the macro grid it lies on. :param radius: footprint radius of a part [m].
    :raises ValueError: if the beam is not along a grid axis.
    """

    def __init__(self, index: int, barrier: LightBarrier, sim: MacroSim, radius: float) -> None:
        self.index = index
        self.sim = sim
        self.length = 2.0 * radius
        g = sim.grid
        (x0, y0), (x1, y1) = barrier.start, barrier.end
        if abs(x1 - x0) <= 1e-9:
            self.axis = 0  # beam along y: flux across x faces
            self.face = min(max(int(round((x0 - g.origin_x) / g.h)), 0), g.nx)
            lo, hi = sorted((y0, y1))
            self.rows = slice(*_span(lo, hi, g.origin_y, g.h, g.ny))
        elif abs(y1 - y0) <= 1e-9:
            self.axis = 1
            self.face = min(max(int(round((y0 - g.origin_y) / g.h)), 0), g.ny)
            lo, hi = sorted((x0, x1))
            self.rows = slice(*_span(lo, hi, g.origin_x, g.h, g.nx))
        else:
            msg = (f'light barrier {barrier.name!r} in macro zone {sim.zone.name!r} is not along '
                   'a grid axis; only beams of constant x or constant y are modelled')
            raise ValueError(msg)
        self.crossings = 0.0
        self.travel = 0.0
        self.blocked = False
        self.edge_count = 0

    def _flux(self) -> Tuple[float, float]:
        """Return (parts crossing per second, flux-weighted normal speed [m/s])."""
        rho = self.sim.density
        ux, uy = self.sim.face_velocity
        f = self.face
        if self.axis == 0:
            u = ux[self.rows, f]
            up = rho[self.rows, max(f - 1, 0)]
            down = rho[self.rows, min(f, rho.shape[1] - 1)]
        else:
            u = uy[f, self.rows]
            up = rho[max(f - 1, 0), self.rows]
            down = rho[min(f, rho.shape[0] - 1), self.rows]
        donor = np.where(u > 0.0, up, down)
        flux = float(np.abs(donor * u).sum()) * self.sim.grid.h
        weight = float(np.abs(donor * u).sum())
        if weight > 0.0:
            speed = float((donor * u * u).sum()) / weight
        else:
            speed = float(np.abs(u).mean()) if u.size else 0.0
        return flux, abs(speed)

    def advance(self, dt: float, t_end: float, out: List[Tuple[int, bool, float]]) -> None:
        """Advance the model over the step ending at ``t_end`` [s]; append edges to ``out``.

        :param out: receives ``(barrier index, blocked, time [s])``.
        """
        rate, speed = self._flux()
        q = rate * dt
        c0 = self.crossings
        c1 = c0 + q
        step_travel = speed * dt
        t0 = t_end - dt
        pos = 0.0
        k = int(np.floor(c0)) + 1
        while q > 0.0 and k <= c1:
            frac = (k - c0) / q
            self._move(out, step_travel, pos, frac, t0, dt)
            if not self.blocked:
                self._edge(out, True, t0 + frac * dt)
            self.travel = 0.0
            pos = frac
            k += 1
        self._move(out, step_travel, pos, 1.0, t0, dt)
        self.crossings = c1

    def _move(self, out: List[Tuple[int, bool, float]], step_travel: float, f0: float,
              f1: float, t0: float, dt: float) -> None:
        """Let the last virtual part travel from step fraction ``f0`` to ``f1``."""
        if not self.blocked:
            return
        gained = step_travel * (f1 - f0)
        if step_travel > 0.0 and self.travel + gained >= self.length:
            f_clear = f0 + (self.length - self.travel) / step_travel
            self._edge(out, False, t0 + min(f_clear, f1) * dt)
            self.travel = self.length
        else:
            self.travel += gained

    def _edge(self, out: List[Tuple[int, bool, float]], blocked: bool, t: float) -> None:
        self.blocked = blocked
        self.edge_count += 1
        out.append((self.index, blocked, t))


def _span(lo: float, hi: float, origin: float, h: float, n: int) -> Tuple[int, int]:
    a = min(max(int(np.floor((lo - origin) / h)), 0), n)
    b = min(max(int(np.ceil((hi - origin) / h)), 0), n)
    return a, max(a, b)
