"""The seam between the test harness and the way a twin is assembled.

:func:`start_layout` is the only place that knows how a lockstep twin of a cell is built and
started, composed in this process or split over three processes; the harness talks to whatever
it starts through ROS alone (services, streams, commands), so switching the assembly touches
this module only. The split processes are started by the one launcher of the split layout
(:func:`conveyor_twin.split.launch.launch`), each writing a log file.
"""

import os
from pathlib import Path
from typing import List, Optional, Tuple

from rclpy.context import Context

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord.layout import Layout
from conveyor_twin.coord.stages import MacroStage
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.split.launch import launch, ros_args, SplitProcesses
from conveyor_twin.testing.processes import RosProcesses

#: The layouts a lockstep twin can run in.
LAYOUTS = tuple(Layout)
__all__ = ['density_per_step', 'LAYOUTS', 'RunningLayout', 'start_layout']


def density_per_step(cell: Cell) -> int:
    """Return the number of ``density`` messages the twin publishes per step (one per grid)."""
    return len(MacroStage(cell).grids)


class RunningLayout:
    """A started lockstep twin: the in-process composition or the split processes.

    :param composed: the in-process twin (composed layout), else None
    :param processes: the twin's processes (split layout), else None
    :param split: the split processes as the launcher started them, else None
    """

    def __init__(self, *, composed: Optional[object] = None,
                 processes: Optional[RosProcesses] = None,
                 split: Optional[SplitProcesses] = None) -> None:
        self.composed = composed
        self.processes = processes
        self.split = split
        self._stopping = False

    def logs(self) -> str:
        """Return the last lines each split process wrote ('' when composed)."""
        return self.split.logs() if self.split is not None else ''

    def dead(self) -> List[Tuple[str, int, Path]]:
        """Return the split processes that ended while the twin runs: (node name, exit code,
        log file); none once :meth:`stop` began."""
        if self._stopping or self.split is None:
            return []
        return [(c.name, c.proc.returncode, c.log) for c in self.split.dead()]

    def stop(self) -> None:
        """Stop the twin (and its processes, cleaning the shared memory they leave)."""
        self._stopping = True
        if self.composed is not None:
            self.composed.stop()
        if self.processes is not None:
            self.processes.stop_all()


def start_layout(cell: Cell, cell_file: Optional[str], *, seed: int, layout: Layout,
                 context: Context, domain_id: int, log_dir: Path, foxglove: str = '',
                 scenario: Optional[object] = None, plc: Optional[object] = None
                 ) -> RunningLayout:
    """Build and start a lockstep twin of ``cell``.

    :param cell: the validated cell
    :param cell_file: the file it was loaded from (None: the embedded default or a cell built in
        memory; the split layout needs a file or the default)
    :param seed: random seed of the run
    :param layout: ``composed`` (this process, ``context``) or ``split`` (three processes)
    :param context: the harness's initialised rclpy context
    :param domain_id: the ROS domain of ``context`` (the split processes join it)
    :param log_dir: where the split processes write their output (``<module>.log``)
    :param foxglove: ``[HOST:]PORT`` of a live Foxglove view; empty: none
    :param scenario: a validated fault scenario to arm, or None
    :param plc: the PLC servers' :class:`~conveyor_twin.plc.options.PlcOptions` (composed
        layout only), or None
    :return: the running twin
    :raises ValueError: on an unknown layout, or a split layout of a cell without a file
    """
    if layout == Layout.COMPOSED:
        from conveyor_twin.ros.compose import ComposedTwin

        twin = ComposedTwin(cell, seed=seed, mode=TimeMode.LOCKSTEP, context=context,
                            markers_rate=0.0, foxglove=foxglove, scenario=scenario, plc=plc)
        twin.start()
        return RunningLayout(composed=twin)
    if layout != Layout.SPLIT:
        raise ValueError(f'layout {layout!r} is not one of {", ".join(LAYOUTS)}')
    if cell_file is None and not cell.source_file.startswith('<embedded'):
        raise ValueError(f'the split layout loads the cell in each process: pass a cell file, '
                         f'not a cell built in memory ({cell.source_file})')
    args = ros_args(os.path.abspath(cell_file) if cell_file else '', seed, 'lockstep', 0.0,
                    None, 0.0, foxglove=foxglove,
                    scenario=os.path.abspath(scenario.source_file) if scenario else '')
    processes = RosProcesses(domain_id=domain_id)
    split = launch(args, start=processes.start, log_dir=log_dir)
    return RunningLayout(processes=processes, split=split)
