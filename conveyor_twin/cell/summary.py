"""One-paragraph human summary of a cell (``conveyor-twin validate``)."""

import math

from conveyor_twin.cell.model import Belt, Cell


def _names(items: tuple) -> str:
    return ', '.join(item.name for item in items) if items else 'none'


def _belt(b: Belt) -> str:
    shape = f'{b.name} {b.length:g} m x {b.width:g} m'
    if b.curve is not None:
        c = b.curve
        turn = 'ccw' if c.direction > 0 else 'cw'
        shape += (f' ({abs(math.degrees(c.sweep)):g} deg {turn} curve, radius '
                  f'{c.inner_radius:g}..{c.outer_radius:g} m' + (', guide rails)' if c.guide_rails
                                                                  else ')'))
    return (f'{shape} at {b.speed:g} m/s (max {b.max_speed:g} m/s, {b.acceleration:g} m/s^2, '
            f'mu {b.friction:g})')


def summarize(cell: Cell) -> str:
    """Return a one-paragraph summary of ``cell``: geometry, parts, flow, sensors, actuators."""
    s = cell.settings
    x0, y0, x1, y1 = cell.bounds
    belts = '; '.join(_belt(b) for b in cell.belts)
    parts = '; '.join(
        f'{p.name} ({p.shape} ' + (f'r {p.radius * 1e3:g} mm' if p.shape == 'disc'
                                   else f'{p.length * 1e3:g} x {p.width * 1e3:g} mm')
        + f', {p.mass * 1e3:g} g)' for p in cell.part_types)
    sources = '; '.join(f'{src.name} {src.rate:g} parts/s {src.pattern} of {src.part_type}'
                        for src in cell.sources) or 'none'
    zones = '; '.join(f'{z.name} {z.policy} ({z.resolution * 1e3:g} mm grid)' for z in cell.zones)
    return (
        f"Cell '{s.name}' from {cell.source_file}: step {s.step * 1e3:g} ms, frame "
        f"'{s.frame_id}', seed {s.seed}, extent x {x0:g}..{x1:g} m, y {y0:g}..{y1:g} m. "
        f'{len(cell.belts)} belt(s): {belts}. '
        f'{len(cell.obstacles)} obstacle(s): {_names(cell.obstacles)}. '
        f'{len(cell.part_types)} part type(s): {parts}. Sources: {sources}. '
        f'Sinks: {_names(cell.sinks)}. Light barriers: {_names(cell.light_barriers)}. '
        f'Actuators: ' + (', '.join(f'{a.name} ({a.kind})' for a in cell.actuators) or 'none')
        + f'. Zones: {zones}. Micro contact model {cell.micro.contact} (capacity '
        f'{cell.micro.capacity} parts); macro model {cell.macro.variant}/{cell.macro.scheme}, '
        f'rho_max {cell.rho_max:.0f} parts/m^2.'
    )
