"""The seam between the test harness and the way a twin is assembled.

:func:`start_layout` is the only place that knows how a lockstep twin of a cell is built and
started, composed in this process or split over three processes; the harness talks to whatever
it starts through ROS alone (services, streams, commands), so switching the assembly touches
this module only.
"""

import os
from pathlib import Path
import subprocess
import sys
from typing import List, Literal, Optional, Tuple

from rclpy.context import Context

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord.stages import MacroStage
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.testing.processes import RosProcesses

Layout = Literal['composed', 'split']
LAYOUTS = ('composed', 'split')
SPLIT_MODULES = ('conveyor_twin.ros.micro_node', 'conveyor_twin.ros.macro_node',
                 'conveyor_twin.ros.split')
#: The node each split module runs (the name a failure is reported by).
SPLIT_NODES = {'micro_node': 'micro_simulator', 'macro_node': 'macro_simulator',
               'split': 'scale_coordinator'}
LOG_TAIL = 2000  # characters of a process's log quoted in a failure [1]


def log_tail(path: Path, size: int = LOG_TAIL) -> str:
    """Return the last ``size`` characters of a log file ('' if there is none)."""
    try:
        return path.read_text(errors='replace')[-size:]
    except OSError:
        return ''


def density_per_step(cell: Cell) -> int:
    """Return the number of ``density`` messages the twin publishes per step (one per grid)."""
    return len(MacroStage(cell).grids)


class RunningLayout:
    """A started lockstep twin: the in-process composition or the split processes.

    :param composed: the in-process twin (composed layout), else None
    :param processes: the twin's processes (split layout), else None
    :param children: the split processes: (node name, process, log file)
    """

    def __init__(self, *, composed: Optional[object] = None,
                 processes: Optional[RosProcesses] = None,
                 children: Tuple[Tuple[str, subprocess.Popen, Path], ...] = ()) -> None:
        self.composed = composed
        self.processes = processes
        self.children = children
        self._stopping = False

    def logs(self) -> str:
        """Return the last lines each split process wrote ('' when composed)."""
        return '\n'.join(f'--- {log.name}\n{log_tail(log)}' for _, _, log in self.children)

    def dead(self) -> List[Tuple[str, int, Path]]:
        """Return the split processes that ended while the twin runs: (node name, exit code,
        log file); none once :meth:`stop` began."""
        if self._stopping:
            return []
        return [(name, code, log) for name, process, log in self.children
                if (code := process.poll()) is not None]

    def stop(self) -> None:
        """Stop the twin (and its processes, cleaning the shared memory they leave)."""
        self._stopping = True
        if self.composed is not None:
            self.composed.stop()
        if self.processes is not None:
            self.processes.stop_all()


def start_layout(cell: Cell, cell_file: Optional[str], *, seed: int, layout: Layout,
                 context: Context, domain_id: int, log_dir: Path, foxglove: str = '',
                 scenario: Optional[object] = None) -> RunningLayout:
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
    from conveyor_twin.ros.split import ros_args, SCALE_PIDS_ENV

    args = ros_args(os.path.abspath(cell_file) if cell_file else '', seed, 'lockstep', 0.0,
                    None, 0.0, foxglove=foxglove,
                    scenario=os.path.abspath(scenario.source_file) if scenario else '')
    processes = RosProcesses(domain_id=domain_id)
    children = []
    env = {}
    for module in SPLIT_MODULES:
        short = module.rsplit('.', 1)[1]
        path = log_dir / f'{short}.log'
        if module == SPLIT_MODULES[-1]:  # the coordinator: it watches the scale processes
            env[SCALE_PIDS_ENV] = ','.join(f'{name}={process.pid}'
                                           for name, process, _ in children)
        with open(path, 'w') as log:
            process = processes.start([sys.executable, '-m', module] + args, env=env,
                                      stdout=log, stderr=log)
        children.append((SPLIT_NODES[short], process, path))
    return RunningLayout(processes=processes, children=tuple(children))
