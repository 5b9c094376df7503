"""The composed layout: the three nodes and their stages in one process, one executor.

The coordinator steps the stages in memory (no per-step ROS traffic between the nodes); each
node publishes its own streams after every step. An executor thread serves commands and
services; the stepping thread (realtime/fast) is the coordinator core's :class:`Runner`.
Every thread of the twin reports its failure to :attr:`ComposedTwin.health` (the twin's).
"""

import os
import threading
from typing import Dict, Optional

from rclpy.context import Context

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.coord.runner import (raise_thread_priority, raise_threads,
                                        realtime_priority, Runner, thread_ids)
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.faults.scenario import Scenario
from conveyor_twin.health import Health
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.output.producers import CoordinatorOutput, MacroOutput, MicroOutput
from conveyor_twin.plc.attach import attach_plc
from conveyor_twin.plc.options import PlcOptions
from conveyor_twin.ros.coordinator_node import CoordinatorNode
from conveyor_twin.ros.foxglove_bridge import attach
from conveyor_twin.ros.compat import make_executor, spin_until
from conveyor_twin.ros.macro_node import MacroNode
from conveyor_twin.ros.micro_node import MicroNode
from conveyor_twin.ros.params import parameter_overrides
from conveyor_twin.ros.qos import publish_failures
from conveyor_twin.ros.sim_attach import attach_sim_interfaces
from conveyor_twin.viz.foxglove_view import DEFAULT_STREAM_RATE, FoxgloveView


#: Name of the executor thread (and of its failure in the twin's health).
EXECUTOR = 'executor thread'


class ComposedTwin:
    """Micro, macro and coordinator nodes of one cell in this process.

    :param cell: the validated cell.
    :param seed: random seed of the run.
    :param mode: realtime, fast or lockstep.
    :param context: an initialised rclpy Context (tests pass a private one).
    :param max_steps: stop the stepping thread after this many steps (None: run until stop).
    :param foxglove: ``[HOST:]PORT`` of a live Foxglove view to serve; empty: none.
    :param foxglove_rate: rate of the per-step streams sent to Foxglove clients [Hz].
    :param scenario: a validated fault scenario to arm (re-armed after every reset).
    :param plc: the OPC UA / Modbus TCP servers to serve (docs/plc.md); None: none.
    :raises conveyor_twin.viz.foxglove_view.FoxgloveError: if the Foxglove server cannot listen
        at ``foxglove`` (nothing is left running).
    :raises conveyor_twin.plc.address.PlcServerError: if a PLC server cannot listen where
        ``plc`` says (nothing is left running).
    """

    def __init__(self, cell: Cell, *, seed: int, mode: TimeMode, context: Context,
                 namespace: Optional[str] = None, markers_rate: float = 30.0,
                 max_steps: Optional[int] = None, foxglove: str = '',
                 foxglove_rate: float = DEFAULT_STREAM_RATE,
                 scenario: Optional[Scenario] = None,
                 plc: Optional[PlcOptions] = None) -> None:
        self.cell = cell
        self.context = context
        self._foreign_threads = thread_ids()  # those this twin does not start
        self.assembled = build_twin(cell, seed=seed)
        self.micro_stage = self.assembled.micro
        self.macro_stage = self.assembled.macro
        self.twin = self.assembled.twin
        #: The twin's health: every thread of this twin (stepping, executor, markers, recorder
        #: writer, Foxglove view, queued sinks) reports its failure here.
        self.health: Health = self.twin.health
        # a failing step is reported to the health (logged at ERROR by the coordinator node)
        self.runner = Runner(self.twin, mode, max_steps=max_steps)
        #: The armed fault scenario (None without one).
        self.scenario = (self.assembled.arm_scenario(scenario) if scenario is not None
                         else None)
        overrides = parameter_overrides(
            cell_file=cell.source_file if os.path.isfile(cell.source_file) else '', seed=seed,
            mode=mode, markers_rate=markers_rate,
            duration=max_steps * cell.settings.step if max_steps else 0.0, foxglove=foxglove,
            scenario=scenario.source_file if scenario is not None else '')
        #: One frame per step of every stream (the nodes, the recorder and other sinks take it).
        self.output = TwinOutput([
            CoordinatorOutput(self.twin,
                              diagnostics=lambda t: self.coordinator.diagnostics_cdr(t)),
            MicroOutput(self.micro_stage), MacroOutput(self.macro_stage)])
        self.output.health = self.health
        common = dict(context=context, namespace=namespace, markers_rate=markers_rate,
                      step_s=cell.settings.step, parameter_overrides=overrides,
                      output=self.output, health=self.health)
        self.coordinator = CoordinatorNode(self.twin, self.runner, context=context,
                                           namespace=namespace, spawn=self.assembled.spawn,
                                           holds_part=self.assembled.holds_part,
                                           counters=self.counters,
                                           parameter_overrides=overrides, output=self.output)
        self.micro_node = MicroNode(self.micro_stage, **common)
        self.macro_node = MacroNode(self.macro_stage, **common)
        self.twin.step_listeners.append(self.output.on_step)
        #: The ``simulation_interfaces`` server (docs/simulation_interfaces.md; None if that
        #: package is not installed).
        self.sim_interfaces = attach_sim_interfaces(self, namespace)
        if mode is TimeMode.REALTIME:
            self.micro_node.markers_priority = realtime_priority(helper=True)
        self.executor = make_executor(context)
        for node in (self.coordinator, self.micro_node, self.macro_node):
            self.executor.add_node(node)
        self._spin_thread: Optional[threading.Thread] = None
        self._stop_spin = threading.Event()
        self._final_diagnostics = False  # the ERROR diagnostics after a failure was published
        #: The live Foxglove view (None without ``foxglove``).
        self.foxglove: Optional[FoxgloveView] = None
        #: The PLC servers (:class:`~conveyor_twin.plc.attach.PlcServers`; None without ``plc``).
        self.plc = None
        if foxglove or (plc is not None and plc.any):
            try:
                if foxglove:
                    self.foxglove = attach(self, foxglove, stream_rate=foxglove_rate)
                if plc is not None and plc.any:
                    self.plc = attach_plc(self, plc)
                    self.coordinator.add_counters(self.plc.counters)
            except BaseException:
                self.stop()
                raise

    def counters(self) -> Dict[str, float]:
        """Part balance per scale: entered, left through sinks, in flight."""
        micro = dict(self.assembled.micro_counters(),
                     publish_failures=publish_failures(self.micro_node))
        macro = dict(self.assembled.macro_counters(),
                     publish_failures=publish_failures(self.macro_node))
        return {**{f'micro_{k}': v for k, v in micro.items()},
                **{f'macro_{k}': v for k, v in macro.items()}}

    def _spin(self) -> None:
        if self.runner.mode is TimeMode.REALTIME:
            raise_thread_priority(realtime_priority(helper=True))
        spin_until(self.executor, self._stop_spin)

    def start(self) -> None:
        """Start serving ROS callbacks and, in realtime/fast mode, stepping.

        In realtime every thread this twin started (the middleware's, the Foxglove view's)
        gets the helper priority first (:func:`~conveyor_twin.coord.runner.raise_threads`).
        """
        if self.runner.mode is TimeMode.REALTIME:
            raise_threads(thread_ids() - self._foreign_threads, realtime_priority(helper=True))
        self._spin_thread = threading.Thread(target=self.health.guard(EXECUTOR, self._spin),
                                             name='conveyor_twin_executor', daemon=True)
        self._spin_thread.start()
        if self.sim_interfaces is not None:
            self.sim_interfaces.start()
        self.runner.start()

    def stop(self) -> None:
        """Stop stepping, then stop serving callbacks and destroy the nodes.

        After a failure of one of its threads the coordinator first publishes a diagnostics
        message with the ERROR status naming it (and hands it to the sinks, e.g. a recorder).
        """
        self.runner.stop()
        if self.health.failed and not self._final_diagnostics:
            self._final_diagnostics = True
            try:
                self.coordinator.publish_diagnostics()
            except Exception as exc:  # noqa: BLE001 - e.g. the context already shut down
                self.health.report('final diagnostics', exc)
        if self.sim_interfaces is not None:
            self.sim_interfaces.stop()
        self._stop_spin.set()
        if self._spin_thread is not None:
            self._spin_thread.join(5.0)
        self.executor.shutdown(timeout_sec=5.0)
        for node in (self.coordinator, self.micro_node, self.macro_node):
            node.destroy_node()
        if self.foxglove is not None:
            self.foxglove.stop()
        if self.plc is not None:
            self.plc.stop()
