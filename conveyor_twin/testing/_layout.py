"""The seam between the test harness and the way a twin is assembled.

:func:`start_layout` is the only place that knows how a lockstep twin of a cell is built and
started, composed in this process or split over three processes; the harness talks to whatever
it starts through ROS alone (services, streams, commands), so switching the assembly touches
this module only.
"""

import os
from pathlib import Path
import sys
import tempfile
from typing import Literal, Optional

from rclpy.context import Context

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord.stages import MacroStage
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.testing.processes import RosProcesses

Layout = Literal['composed', 'split']
LAYOUTS = ('composed', 'split')
SPLIT_MODULES = ('conveyor_twin.ros.micro_node', 'conveyor_twin.ros.macro_node',
                 'conveyor_twin.ros.split')


def density_per_step(cell: Cell) -> int:
    """Return the number of ``density`` messages the twin publishes per step (one per grid)."""
    return len(MacroStage(cell).grids)


class RunningLayout:
    """A started lockstep twin: the in-process composition or the split processes.

    :param composed: the in-process twin (composed layout), else None
    :param processes: the twin's processes (split layout), else None
    :param log_dir: where the split processes write their output
    """

    def __init__(self, *, composed: Optional[object] = None,
                 processes: Optional[RosProcesses] = None,
                 log_dir: Optional[Path] = None) -> None:
        self.composed = composed
        self.processes = processes
        self.log_dir = log_dir

    def logs(self) -> str:
        """Return the last lines each split process wrote ('' when composed)."""
        if self.log_dir is None:
            return ''
        return '\n'.join(f'--- {p.name}\n{p.read_text(errors="replace")[-2000:]}'
                         for p in sorted(self.log_dir.glob('*.log')))

    def stop(self) -> None:
        """Stop the twin (and its processes, cleaning the shared memory they leave)."""
        if self.composed is not None:
            self.composed.stop()
        if self.processes is not None:
            self.processes.stop_all()


def start_layout(cell: Cell, cell_file: Optional[str], *, seed: int, layout: Layout,
                 context: Context, domain_id: int, foxglove: str = '',
                 scenario: Optional[object] = None) -> RunningLayout:
    """Build and start a lockstep twin of ``cell``.

    :param cell: the validated cell
    :param cell_file: the file it was loaded from (None: the embedded default or a cell built in
        memory; the split layout needs a file or the default)
    :param seed: random seed of the run
    :param layout: ``composed`` (this process, ``context``) or ``split`` (three processes)
    :param context: the harness's initialised rclpy context
    :param domain_id: the ROS domain of ``context`` (the split processes join it)
    :param foxglove: ``[HOST:]PORT`` of a live Foxglove view; empty: none
    :param scenario: a validated fault scenario to arm, or None
    :return: the running twin
    :raises ValueError: on an unknown layout, or a split layout of a cell without a file
    """
    if layout == 'composed':
        from conveyor_twin.ros.compose import ComposedTwin

        twin = ComposedTwin(cell, seed=seed, mode=TimeMode.LOCKSTEP, context=context,
                            markers_rate=0.0, foxglove=foxglove, scenario=scenario)
        twin.start()
        return RunningLayout(composed=twin)
    if layout != 'split':
        raise ValueError(f'layout {layout!r} is not one of {", ".join(LAYOUTS)}')
    if cell_file is None and not cell.source_file.startswith('<embedded'):
        raise ValueError(f'the split layout loads the cell in each process: pass a cell file, '
                         f'not a cell built in memory ({cell.source_file})')
    from conveyor_twin.ros.split import ros_args

    args = ros_args(os.path.abspath(cell_file) if cell_file else '', seed, 'lockstep', 0.0,
                    None, 0.0, foxglove=foxglove,
                    scenario=os.path.abspath(scenario.source_file) if scenario else '')
    processes = RosProcesses(domain_id=domain_id)
    log_dir = Path(tempfile.mkdtemp(prefix='conveyor_twin_split_'))
    for module in SPLIT_MODULES:
        with open(log_dir / f'{module.rsplit(".", 1)[1]}.log', 'w') as log:
            processes.start([sys.executable, '-m', module] + args, stdout=log, stderr=log)
    return RunningLayout(processes=processes, log_dir=log_dir)
