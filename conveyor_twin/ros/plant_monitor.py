"""The plant-wide view over ROS 2: every cell's ``progress``, the ledger, the plant's diagnostics.

:class:`PlantMonitor` keeps the latest report of every cell (as a plain
:class:`~conveyor_twin.plant.ledger.CellReport`) and the last report of every cell run that
ended, builds the plant-wide ledger from them (:func:`~conveyor_twin.plant.ledger.ledger_of`)
and publishes it on the plant's ``diagnostics`` (status ``conveyor_twin: plant``). Failures it
learns of (a cell process that died, its own callback raising) go to its
:class:`~conveyor_twin.health.Health`; the status is then ERROR and names them.
"""

from typing import Dict, List, Optional, Set, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.context import Context
from rclpy.node import Node

from conveyor_twin import contract
from conveyor_twin.coord.clock import stamp, step_ns
from conveyor_twin.health import Health
from conveyor_twin.plant.ledger import CellReport, PlantLedger, ledger_of
from conveyor_twin.plant.model import Plant
from conveyor_twin.ros.plant_messages import CellProgress, report_of
from conveyor_twin.ros.qos import to_rclpy


class PlantMonitor:
    """The plant-wide view: every cell's latest ``progress``, the ledger, and the plant's
    ``diagnostics`` (status ``conveyor_twin: plant``).

    :param plant: the validated plant. :param context: an initialised rclpy Context.
    :param health: where failures are reported (default: a new one, :attr:`health`).
    """

    def __init__(self, plant: Plant, *, context: Context,
                 health: Optional[Health] = None) -> None:
        self.plant = plant
        self.health = health if health is not None else Health()
        self.reports: Dict[str, CellReport] = {}
        #: The last report of every cell run that ended (another run of the cell reported).
        self.ended: List[CellReport] = []
        self._ended_runs: Set[Tuple[str, int]] = set()
        self.node = Node('plant_monitor', namespace='/' + plant.namespace, context=context)
        self._sub = self.node.create_subscription(
            CellProgress, contract.CELL_PROGRESS.name,
            self.health.guard('plant monitor (progress)', self._on_progress),
            to_rclpy(contract.CELL_PROGRESS.qos))
        self._diag = self.node.create_publisher(DiagnosticArray,
                                                contract.PLANT_DIAGNOSTICS.name,
                                                to_rclpy(contract.PLANT_DIAGNOSTICS.qos))

    def _on_progress(self, msg: 'CellProgress') -> None:
        self.take(report_of(msg))

    def take(self, report: CellReport) -> None:
        """Take a cell's report: a report of another run ends the cell's earlier run (late
        reports of an ended run are ignored)."""
        if (report.cell, report.run) in self._ended_runs:
            return  # a late report of a run that ended
        old = self.reports.get(report.cell)
        if old is not None and old.run != report.run:
            self.ended.append(old)
            self._ended_runs.add((old.cell, old.run))
        self.reports[report.cell] = report

    def ledger(self) -> PlantLedger:
        """Return the plant-wide ledger from the latest reports."""
        return ledger_of(dict(self.reports), list(self.ended))

    def steps(self) -> Dict[str, int]:
        """Return every cell's last reported step of its current run (-1: no report yet)."""
        return {c.name: int(self.reports[c.name].step) if c.name in self.reports else -1
                for c in self.plant.cells}

    def simulated_steps(self) -> Dict[str, int]:
        """Return the steps every cell simulated over all its runs (-1: no report yet): a
        restarted cell counts its ended runs' last reported steps plus its current run's."""
        out = self.steps()
        for m in self.ended:
            if out.get(m.cell, -1) >= 0:
                out[m.cell] += int(m.step)
        return out

    def restarts(self) -> Dict[str, int]:
        """Return, per cell, how many of its runs ended (0: never restarted)."""
        counts = {c.name: 0 for c in self.plant.cells}
        for m in self.ended:
            counts[m.cell] = counts.get(m.cell, 0) + 1
        return counts

    def gone_unfinished(self) -> List[str]:
        """Return the cells that reported, are not done, and whose node is not in the ROS
        graph (it publishes no ``progress``): a cell process that ended or died before its
        ``done`` report reached the monitor (for cells in processes of their own)."""
        topic = self._sub.topic_name
        present = {i.node_name for i in self.node.get_publishers_info_by_topic(topic)}
        return [c.name for c in self.plant.cells
                if c.name in self.reports and not self.reports[c.name].done
                and contract.plant_cell_node(c.name) not in present]

    def all_done(self) -> bool:
        """True once every cell reported it completed the end step."""
        return all(c.name in self.reports and self.reports[c.name].done
                   for c in self.plant.cells)

    def status(self) -> DiagnosticStatus:
        """Return the ``conveyor_twin: plant`` status: the ledger, every cell's step; ERROR
        naming what failed (:attr:`health`), WARN if the done reports do not balance."""
        ledger = self.ledger()
        values = {k: f'{v:g}' for k, v in ledger.as_dict().items()}
        steps = self.steps()
        values.update({f'cell_{k}_step': str(v) for k, v in steps.items()})
        values.update({f'cell_{k}_restarts': str(v) for k, v in self.restarts().items() if v})
        lowest = min(steps.values()) if steps else 0
        message = f'{len(steps)} cells, slowest at step {lowest}; in links {ledger.in_links}'
        failed, what = self.health.status()
        if failed:
            level = DiagnosticStatus.ERROR
            message = what + '; ' + message
            values['failures'] = what
        elif ledger.residual != 0.0 and self.all_done():
            level = DiagnosticStatus.WARN
        else:
            level = DiagnosticStatus.OK
        return DiagnosticStatus(level=level, name='conveyor_twin: plant',
                                hardware_id=self.plant.name, message=message,
                                values=[KeyValue(key=k, value=v) for k, v in values.items()])

    def publish_diagnostics(self) -> None:
        """Publish :meth:`status` on the plant's ``diagnostics``."""
        status = self.status()
        lowest = min(self.simulated_steps().values(), default=0)
        msg = DiagnosticArray(status=[status])
        msg.header.stamp.sec, msg.header.stamp.nanosec = stamp(
            max(lowest, 0) * step_ns(self.plant.step))
        self._diag.publish(msg)

    def destroy(self) -> None:
        """Destroy the node."""
        self.node.destroy_node()
