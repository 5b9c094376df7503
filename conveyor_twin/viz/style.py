"""Conventions shared by the figures and the animation: density colours, commanded vs actual.

The macro density is drawn with one colour map on a scale from 0 to the cell's cap ρ_max
(``macro.rho_max``, or hexagonal packing of the first part type) when the cell is known, so
the colour reads as a fraction of the cap in every picture; without the cell (or should the
density exceed the cap) the scale ends at the largest density shown.
"""

from typing import Iterable, Optional, Sequence

import numpy as np

#: Colour map of the macro density (perceptually uniform, readable in grey).
DENSITY_CMAP = 'viridis'
#: Colour bar label of the macro density (unit: docs/models.md).
DENSITY_LABEL = 'density ρ [parts/m²]'


def density_vmax(grids: Iterable, rho_max: Optional[float]) -> float:
    """Return the top of the density colour scale [parts/m²].

    :param grids: the density grids shown (objects with a ``density`` array [parts/m²]).
    :param rho_max: the cell's cap [parts/m²], or None when the cell is unknown.
    """
    peak = max([float(np.max(g.density)) for g in grids if np.size(g.density)] + [0.0])
    if rho_max is not None and rho_max > 0.0:
        return max(float(rho_max), peak)
    return peak if peak > 0.0 else 1.0


def density_scale_text(vmax: float, rho_max: Optional[float]) -> str:
    """Return what the top of the density scale is, e.g. ``0..ρ_max = 11547 parts/m²``."""
    if rho_max is not None and 0.0 < vmax <= rho_max:
        return f'scale 0..ρ_max = {vmax:.0f} parts/m²'
    return f'scale 0..{vmax:.0f} parts/m² (largest shown)'


def commanded_and_actual(ax, t: np.ndarray, actual: np.ndarray, commanded: np.ndarray,
                         names: Sequence[str], *, fontsize: float = 7.0) -> None:
    """Draw actual (wide pale band) and commanded (thin dashed, on top) per name on ``ax``.

    Both stay visible where they coincide. The legend names each colour once and the two
    styles once.
    """
    from matplotlib.lines import Line2D

    handles = []
    for k, name in enumerate(names):
        band, = ax.plot(t, actual[:, k], '-', lw=4.0, alpha=0.35, solid_capstyle='butt',
                        zorder=2)
        colour = band.get_color()
        if commanded.ndim == 2 and commanded.shape[1] > k:
            ax.plot(t, commanded[:, k], '--', lw=1.1, color=colour, zorder=3,
                    dashes=(4, 2))
        handles.append(Line2D([], [], color=colour, lw=2.0, label=name))
    if not names:
        return
    handles.append(Line2D([], [], color='0.3', lw=4.0, alpha=0.35, label='actual'))
    handles.append(Line2D([], [], color='0.3', lw=1.1, ls='--', dashes=(4, 2),
                          label='commanded'))
    ax.legend(handles=handles, fontsize=fontsize, loc='best', ncol=2 if len(names) > 2 else 1,
              framealpha=0.85)
