"""The plant-wide part ledger: entered = in cells + in links + left (+ vanished).

Built from what each cell reports (:meth:`~conveyor_twin.plant.cell.PlantCellCore.counts`) and,
per link, from its exit (parts sent and not reported inserted: in transit, waiting at a
blocked entry, or held for an entry cell that is not running). Reports from cells that run in
processes of their own may be from different steps; the ledger balances exactly for their
final reports (each cell's ``done`` report comes after its exits heard their entries' final
batches) and says by how much it does not.
"""

from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Sequence


@dataclass
class CellReport:
    """What one run of a cell reported last (the ``CellProgress`` message as plain data).

    Counts in parts; per exit link (``exit_*``, in plant order) parts sent, reported inserted
    by the entry and re-sent to a restarted entry cell; per entry link (``entry_*``) parts
    inserted, due and waiting, inserted of earlier runs of the exit cell and dropped with them.
    ``step``: steps the run completed; ``done``: it completed its last step and settled.
    """

    cell: str
    run: int = 0
    step: int = 0
    done: bool = False
    entered: float = 0.0
    in_cell: float = 0.0
    left: float = 0.0
    vanished: float = 0.0
    exit_link: List[str] = field(default_factory=list)
    exit_sent: List[int] = field(default_factory=list)
    exit_accepted: List[int] = field(default_factory=list)
    exit_resent: List[int] = field(default_factory=list)
    entry_link: List[str] = field(default_factory=list)
    entry_inserted: List[int] = field(default_factory=list)
    entry_waiting: List[int] = field(default_factory=list)
    entry_earlier: List[int] = field(default_factory=list)
    entry_dropped: List[int] = field(default_factory=list)
    state_hash: str = ''
    real_time_factor: float = 0.0


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
    #: links (:func:`ledger_of`).
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


def ledger_of(reports: Mapping[str, CellReport],
              ended: Sequence[CellReport] = ()) -> PlantLedger:
    """Return the plant-wide ledger from the latest report of every cell and the last reports
    of cell runs that ended (a process killed or restarted).

    A link's parts are as its exit cell's current run reports them: sent, and inserted as the
    entry reported to the exit (the rest the exit still holds). A run that ended keeps what
    entered and left through it; what it held is ``lost``:

    - what was in the cell at its last report;
    - as an entry cell: what it inserted and reported to the exit after that report (what it
      inserted and did not report, the exit still holds and sends to the next run);
    - as an exit cell: what it sent by its last report less what the entry inserted of the
      parts of ended runs (the rest the entry dropped, or never received).

    If that sum is negative for a cell (parts that entered a source cell after its last
    report reached the next cell), it counts as entered instead. Exact for the cells' done
    reports (settled: every exit heard its entry's final batch) and one restarted cell per
    link at a time; while cells run, a link's counts may lag its entry cell's by a batch.
    """
    cells: Dict[str, Dict[str, float]] = {}
    reported: Dict[str, int] = {}      # per link: insertions of the current exit run's parts
    earlier: Dict[str, int] = {}       # per link: insertions of ended exit runs' parts
    waiting: Dict[str, int] = {}
    net: Dict[str, float] = {}         # per cell with ended runs: what they held
    ended_links: Dict[str, str] = {}   # link -> its entry cell, for ended entry runs
    ended_sent: Dict[str, int] = {}    # link -> sent by ended exit runs
    ended_exit: Dict[str, str] = {}    # link -> its exit cell, for ended exit runs
    for m in (*ended, *reports.values()):
        current = reports.get(m.cell) is m
        key = m.cell if current else f'{m.cell}#{m.run}'
        cells[key] = {'entered': m.entered, 'in_cell': m.in_cell if current else 0.0,
                      'left': m.left, 'vanished': m.vanished}
        if not current:
            net[m.cell] = net.get(m.cell, 0.0) + m.in_cell
            ended_links.update((name, m.cell) for name in m.entry_link)
            for name, sent in zip(m.exit_link, m.exit_sent):
                ended_sent[name] = ended_sent.get(name, 0) + int(sent)
                ended_exit[name] = m.cell
        for name, n, w, e in zip(m.entry_link, m.entry_inserted, m.entry_waiting,
                                 m.entry_earlier or [0] * len(m.entry_link)):
            reported[name] = reported.get(name, 0) + int(n) - int(e)
            earlier[name] = earlier.get(name, 0) + int(e)
            if current:
                waiting[name] = int(w)
    links = {}
    for m in reports.values():
        for name, sent, acc, res in zip(m.exit_link, m.exit_sent, m.exit_accepted,
                                        m.exit_resent):
            links[name] = LinkCounts(int(sent), int(acc), waiting.get(name, 0), int(res))
            if name in ended_links:
                cell = ended_links[name]
                net[cell] += max(0, int(acc) - reported.get(name, 0))
    for name, cell in ended_exit.items():
        net[cell] += ended_sent[name] - earlier.get(name, 0)
    lost = 0.0
    for cell, held in net.items():
        if held >= 0:
            lost += held
        else:
            cells[f'{cell}#unreported'] = {'entered': -held, 'in_cell': 0.0, 'left': 0.0,
                                           'vanished': 0.0}
    return PlantLedger(cells, links, lost)
