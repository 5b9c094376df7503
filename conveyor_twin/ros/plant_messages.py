"""The plant's messages and the link ends' batches: pure conversions both ways.

``PartTransfer`` carries a :class:`~conveyor_twin.plant.link.Departures` batch,
``TransferAccepted`` an :class:`~conveyor_twin.plant.link.Acceptances` batch, ``CellProgress``
a cell's counts (:func:`progress_msg`; :func:`report_of` turns it into the plain
:class:`~conveyor_twin.plant.ledger.CellReport` the ledger is computed from).
"""

from conveyor_twin import contract
from conveyor_twin.coord.clock import stamp, step_ns
from conveyor_twin.coord.timing import StepStats
from conveyor_twin.plant.cell import PlantCellCore
from conveyor_twin.plant.ledger import CellReport
from conveyor_twin.plant.link import Acceptances, Departures, Transit
from conveyor_twin.ros.endpoints import message_class

PartTransfer = message_class(contract.PART_TRANSFER.type_name)
TransferAccepted = message_class(contract.TRANSFER_ACCEPTED.type_name)
CellProgress = message_class(contract.CELL_PROGRESS.type_name)


def departures_msg(batch: Departures, time_ns: int) -> 'PartTransfer':
    """Return the ``PartTransfer`` message of a batch of departures."""
    m = PartTransfer()
    m.header.stamp.sec, m.header.stamp.nanosec = stamp(time_ns)
    m.header.frame_id = batch.link
    m.link, m.through = batch.link, batch.through
    m.first_seq, m.held_from = batch.first_seq, batch.held_from
    m.run = batch.run
    p = batch.parts
    m.step_left = [t.step for t in p]
    m.id = [t.id for t in p]
    m.origin_id = [t.origin for t in p]
    m.part_type = [t.part_type for t in p]
    m.x, m.y, m.yaw = [t.x for t in p], [t.y for t in p], [t.yaw for t in p]
    m.vx, m.vy, m.wz = [t.vx for t in p], [t.vy for t in p], [t.wz for t in p]
    return m


def departures_of(m: 'PartTransfer') -> Departures:
    """Return the batch of departures a ``PartTransfer`` message carries."""
    parts = [Transit(m.first_seq + i, int(s), int(pid), int(o), int(t), float(x), float(y),
                     float(a), float(vx), float(vy), float(w))
             for i, (s, pid, o, t, x, y, a, vx, vy, w) in enumerate(zip(
                 m.step_left, m.id, m.origin_id, m.part_type, m.x, m.y, m.yaw, m.vx, m.vy,
                 m.wz))]
    return Departures(m.link, int(m.through), int(m.first_seq), int(m.held_from), parts,
                      int(m.run))


def acceptances_msg(batch: Acceptances, time_ns: int) -> 'TransferAccepted':
    """Return the ``TransferAccepted`` message of a batch of acceptances."""
    m = TransferAccepted()
    m.header.stamp.sec, m.header.stamp.nanosec = stamp(time_ns)
    m.header.frame_id = batch.link
    m.link, m.through, m.run = batch.link, batch.through, batch.run
    m.seq, m.step = list(batch.seq), list(batch.step)
    m.starting = batch.starting
    m.exit_run_known = batch.exit_run is not None
    m.exit_run = batch.exit_run if batch.exit_run is not None else 0
    m.final = batch.final
    return m


def acceptances_of(m: 'TransferAccepted') -> Acceptances:
    """Return the batch of acceptances a ``TransferAccepted`` message carries."""
    return Acceptances(m.link, int(m.through), int(m.run), [int(s) for s in m.seq],
                       [int(s) for s in m.step], starting=bool(m.starting),
                       exit_run=int(m.exit_run) if m.exit_run_known else None,
                       final=bool(m.final))


def progress_msg(core: PlantCellCore, *, end_step: int, done: bool, stats: StepStats,
                 rtf: float, with_hash: bool) -> 'CellProgress':
    """Return a ``CellProgress`` message of a cell now (``with_hash``: its state digest)."""
    r = core.report(done=done, with_hash=with_hash)
    m = CellProgress()
    m.header.stamp.sec, m.header.stamp.nanosec = stamp(r.step * step_ns(core.plant.step))
    m.header.frame_id = r.cell
    m.cell, m.step, m.end_step, m.done, m.run = r.cell, r.step, end_step, done, r.run
    m.entered, m.in_cell, m.left, m.vanished = r.entered, r.in_cell, r.left, r.vanished
    m.exit_link, m.exit_sent = r.exit_link, r.exit_sent
    m.exit_accepted, m.exit_resent = r.exit_accepted, r.exit_resent
    m.entry_link, m.entry_inserted, m.entry_waiting = (r.entry_link, r.entry_inserted,
                                                       r.entry_waiting)
    m.entry_earlier, m.entry_dropped = r.entry_earlier, r.entry_dropped
    m.step_time_mean_ms = stats.total()['mean_ms'] if stats.count else 0.0
    m.real_time_factor = rtf
    m.state_hash = r.state_hash
    return m


def report_of(m: 'CellProgress') -> CellReport:
    """Return the plain report of a ``CellProgress`` message (what the ledger needs)."""
    n_entries = len(m.entry_link)
    return CellReport(
        cell=m.cell, run=int(m.run), step=int(m.step), done=bool(m.done),
        entered=float(m.entered), in_cell=float(m.in_cell), left=float(m.left),
        vanished=float(m.vanished), exit_link=list(m.exit_link),
        exit_sent=[int(v) for v in m.exit_sent],
        exit_accepted=[int(v) for v in m.exit_accepted],
        exit_resent=[int(v) for v in m.exit_resent], entry_link=list(m.entry_link),
        entry_inserted=[int(v) for v in m.entry_inserted],
        entry_waiting=[int(v) for v in m.entry_waiting],
        entry_earlier=[int(v) for v in m.entry_earlier] or [0] * n_entries,
        entry_dropped=[int(v) for v in m.entry_dropped] or [0] * n_entries,
        state_hash=m.state_hash, real_time_factor=float(m.real_time_factor))
