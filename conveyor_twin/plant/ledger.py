"""The plant-wide part ledger: entered = in cells + in links + left (+ vanished).

Built from what each cell reports (:meth:`~conveyor_twin.plant.cell.PlantCellCore.counts`) and,
per link, from its exit (parts sent and not reported inserted: in transit, waiting at a
blocked entry, or held for an entry cell that is not running). Reports from cells that run in
processes of their own may be from different steps; the ledger balances exactly for their
final reports (each cell's ``done`` report comes after its exits heard their entries' final
batches) and says by how much it does not.
"""

from dataclasses import dataclass, field
from typing import Dict, Mapping

#: The per-cell counts a ledger is built from (see ``PlantCellCore.counts``).
CELL_KEYS = ('entered', 'in_cell', 'left', 'vanished', 'sent', 'inserted')


@dataclass
class LinkCounts:
    """One link's part counts [parts]: sent by its exit, reported inserted by its entry,
    held (sent and not inserted), of which due and waiting at the entry, and re-sent to a
    restarted entry cell."""

    sent: int = 0
    inserted: int = 0
    waiting: int = 0
    resent: int = 0

    @property
    def held(self) -> int:
        """Parts in the link [parts]."""
        return self.sent - self.inserted


@dataclass
class PlantLedger:
    """Counts of the whole plant [parts] (fractional where macro density holds parts)."""

    cells: Dict[str, Dict[str, float]] = field(default_factory=dict)
    links: Dict[str, LinkCounts] = field(default_factory=dict)
    #: Parts that died with cell runs that ended (killed, restarted): in the cell or in its
    #: links (:func:`conveyor_twin.ros.plant_node.ledger_of`).
    lost: float = 0.0

    @property
    def entered(self) -> float:
        """Parts that entered the plant (sources and spawns of every cell)."""
        return sum(c['entered'] for c in self.cells.values())

    @property
    def in_cells(self) -> float:
        """Parts in the cells now."""
        return sum(c['in_cell'] for c in self.cells.values())

    @property
    def in_links(self) -> int:
        """Parts in the links now."""
        return sum(k.held for k in self.links.values())

    @property
    def left(self) -> float:
        """Parts that left the plant through sinks."""
        return sum(c['left'] for c in self.cells.values())

    @property
    def vanished(self) -> float:
        """Parts that fell off the line (fault ``parts_vanish``)."""
        return sum(c['vanished'] for c in self.cells.values())

    @property
    def residual(self) -> float:
        """``entered - in_cells - in_links - left - vanished``: 0 when nothing was lost or
        duplicated (for reports of one step)."""
        return (self.entered - self.in_cells - self.in_links - self.left - self.vanished
                - self.lost)

    def as_dict(self) -> Dict[str, float]:
        """Return the totals and the links as a flat mapping (diagnostics, summaries)."""
        out = {'entered': self.entered, 'in_cells': self.in_cells,
               'in_links': float(self.in_links), 'left': self.left,
               'vanished': self.vanished, 'lost': self.lost, 'residual': self.residual}
        for name, k in self.links.items():
            out[f'link_{name}_sent'] = float(k.sent)
            out[f'link_{name}_inserted'] = float(k.inserted)
            out[f'link_{name}_held'] = float(k.held)
            out[f'link_{name}_waiting'] = float(k.waiting)
        return out

    def text(self) -> str:
        """Return the ledger as a few lines for a terminal."""
        lines = [f'ledger: entered {self.entered:g} = in cells {self.in_cells:g} + in links '
                 f'{self.in_links} + left {self.left:g}'
                 + (f' + vanished {self.vanished:g}' if self.vanished else '')
                 + (f' + lost with ended cell processes {self.lost:g}' if self.lost else '')
                 + f' (residual {self.residual:g})']
        for name, k in self.links.items():
            extra = f', re-sent {k.resent}' if k.resent else ''
            lines.append(f'  link {name}: sent {k.sent}, inserted {k.inserted}, held '
                         f'{k.held} (waiting at the entry {k.waiting}){extra}')
        return '\n'.join(lines)


def ledger_from(cells: Mapping[str, Mapping[str, float]],
                links: Mapping[str, LinkCounts], lost: float = 0.0) -> PlantLedger:
    """Build a ledger from per-cell counts and per-link counts."""
    return PlantLedger({k: dict(v) for k, v in cells.items()}, dict(links), lost)
