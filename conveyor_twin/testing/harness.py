"""A lockstep twin for tests: started in-process in a ROS domain of its own, driven over ROS.

:class:`LockstepTwin` starts the twin of a cell (composed in this process, or split over three
processes) in ``lockstep`` mode, in a private rclpy context on a domain id no other test holds
(loopback discovery only), and drives it the way a controller would: through the ``step``,
``spawn_parts`` and ``reset`` services, the command topics and the streams. Nothing it does
reads the twin's internals, so what a test sees is what a controller sees.

It is put together from one part per job: :mod:`~conveyor_twin.testing.lifecycle` (start,
failures, close), :mod:`~conveyor_twin.testing.reading` (what the streams said),
:mod:`~conveyor_twin.testing.stepping` (stepping and waiting),
:mod:`~conveyor_twin.testing.acting` (commands and services) and
:mod:`~conveyor_twin.testing.controllers` (attached nodes and controller processes).
"""

import os
from pathlib import Path
from typing import Any, Optional, Union

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import Cell
from conveyor_twin.coord.layout import Layout
from conveyor_twin.plc.options import PlcOptions
from conveyor_twin.testing import checks
from conveyor_twin.testing._layout import LAYOUTS
from conveyor_twin.testing.acting import Acting
from conveyor_twin.testing.controllers import Controllers
from conveyor_twin.testing.driver import TIMEOUT
from conveyor_twin.testing.reading import DensityGrid, PartStates
from conveyor_twin.testing.states import (ActuatorState, BarrierState, BeltSample, BeltState,
                                          CommandRecord, Edge)
from conveyor_twin.testing.stepping import Stepping

DEFAULT_CHUNK = 10      # steps per ``step`` service call: a controller reacts within this many
DEFAULT_SEED = 0

__all__ = ['ActuatorState', 'BarrierState', 'BeltSample', 'BeltState', 'CommandRecord',
           'DEFAULT_CHUNK', 'DensityGrid', 'Edge', 'LockstepTwin', 'PartStates']


class LockstepTwin(Stepping, Acting, Controllers):
    """A twin in lockstep, started for a test; a context manager.

    :param cell: a cell file, a :class:`~conveyor_twin.cell.model.Cell`, or None for the
        embedded default cell
    :param seed: random seed of the run (an integer in [0, 2**64 - 1])
    :param layout: ``composed`` (one process: this one) or ``split`` (three processes; needs a
        cell file or the default cell)
    :param chunk: steps per ``step`` service call; between calls the harness waits for every
        stream and for the twin's answer to every command, so an attached controller reacts
        within ``chunk`` steps
    :param timeout: longest wait for any one answer of the twin or a controller [s] (> 0)
    :param foxglove: ``[HOST:]PORT`` to serve a live Foxglove view of the test's twin at (watch
        a test step by step); None: no view. Composed: port 0 picks a free one, see
        :attr:`foxglove`; split: the coordinator process serves it, give a port.
    :param scenario: a fault scenario file to arm (``docs/faults.md``); checked before the
        twin starts
    :param opcua: ``[HOST:]PORT`` of an OPC UA server of the twin (``docs/plc.md``; composed
        layout; port 0 picks a free one, see :attr:`plc`); None: none
    :param modbus: ``[HOST:]PORT`` of a Modbus TCP server of the twin, likewise
    :param plc: the PLC servers' other options (read-only, OPC UA security, user, certificate
        folder: :class:`~conveyor_twin.plc.options.PlcOptions`; its addresses are replaced by
        ``opcua`` and ``modbus``); None: the defaults
    :raises ValueError: on an unknown layout, a seed, chunk or timeout out of range (the
        message names it, the value and the range), an invalid ``foxglove`` address, or port 0
        with the split layout
    :raises conveyor_twin.faults.scenario.ScenarioError: on an invalid scenario file
    :raises conveyor_twin.viz.foxglove_view.FoxgloveError: if the view cannot listen there
    :raises conveyor_twin.plc.address.PlcServerError: if a PLC server cannot listen there
    :raises conveyor_twin.cell.CellError: on an invalid cell file

    The twin leaves no trace: the process's environment is not changed (the domain id and
    loopback discovery go to its own rclpy context and its child processes), and its folder
    of logs (split processes, controller processes) is removed at :meth:`close` unless the
    twin failed; then the error names the folder.
    """

    def __init__(self, cell: Union[None, str, Path, Cell] = None, *, seed: int = DEFAULT_SEED,
                 layout: Layout = 'composed', chunk: int = DEFAULT_CHUNK,
                 timeout: float = TIMEOUT, foxglove: Optional[str] = None,
                 scenario: Union[None, str, Path] = None, opcua: Optional[str] = None,
                 modbus: Optional[str] = None, plc: Optional[PlcOptions] = None) -> None:
        seed = checks.integer('seed', seed, 0, checks.UINT64_MAX)
        chunk = checks.integer('chunk', chunk, 1, checks.UINT32_MAX)
        timeout = checks.seconds('timeout', timeout, open_low=True)
        if layout not in LAYOUTS:
            raise ValueError(f'layout {layout!r} is not one of {", ".join(LAYOUTS)}')
        if foxglove is not None:
            from conveyor_twin.viz.foxglove_view import FoxgloveError, parse_address
            try:
                _, port = parse_address(foxglove)
            except FoxgloveError as exc:
                raise ValueError(str(exc)) from None
            if port == 0 and layout == 'split':
                raise ValueError('foxglove: the split layout serves the view from its own '
                                 'process; give a port other than 0')
        plc_options = _plc_options(opcua, modbus, plc, layout)
        cell_file = None if cell is None or isinstance(cell, Cell) else os.fspath(cell)
        self.cell: Cell = cell if isinstance(cell, Cell) else load_cell(cell_file)
        self.scenario = None
        if scenario is not None:
            from conveyor_twin.faults.scenario import load_scenario
            self.scenario = load_scenario(os.fspath(scenario), self.cell)
        self.seed = seed
        self.layout = layout
        self.chunk = chunk
        self.step_s = self.cell.settings.step
        self.step_index = 0
        #: Simulation time of the last step, as the ``step`` service answered it [ns].
        self.time_ns = 0
        self._start(cell_file, timeout=timeout, foxglove=foxglove or '', plc=plc_options)

    def __enter__(self) -> 'LockstepTwin':
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self.close()


def _plc_options(opcua: Optional[str], modbus: Optional[str], plc: Optional[PlcOptions],
                 layout: Layout) -> Optional[PlcOptions]:
    """Return the PLC servers' options of a lockstep twin (None: no server).

    :raises ValueError: on an address that is no ``[HOST:]PORT`` or a server of the split
        layout (the message names it).
    """
    if opcua is None and modbus is None:
        return None
    if layout == Layout.SPLIT:
        raise ValueError('opcua/modbus: the PLC servers need the composed layout (the split '
                         'layout makes the edges in another process)')
    from dataclasses import replace

    from conveyor_twin.plc.address import parse_address
    for name, address in (('opcua', opcua), ('modbus', modbus)):
        if address is not None:
            parse_address(address, option=name)
    return replace(plc or PlcOptions(), opcua=opcua or '', modbus=modbus or '')
