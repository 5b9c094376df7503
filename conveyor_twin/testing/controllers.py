"""Controllers attached to a :class:`~conveyor_twin.testing.LockstepTwin`: nodes of the test's
process, spun whenever the harness waits, and controller processes of their own in the twin's
domain, watched (and paced) by the :class:`~conveyor_twin.testing.supervision.Supervisor`.
"""

import subprocess
from typing import Any, Mapping, Optional, Sequence

from rclpy.node import Node

from conveyor_twin.testing import checks
from conveyor_twin.testing.errors import ConditionNotMet
from conveyor_twin.testing.lifecycle import TwinLifecycle
from conveyor_twin.testing.ros_env import wait_for


class Controllers(TwinLifecycle):
    """The controllers part of :class:`~conveyor_twin.testing.LockstepTwin`."""

    def add_node(self, node: Node) -> Node:
        """Attach a controller node of this process: it is spun whenever the harness waits.

        Create it on :attr:`context` (``MyController(context=twin.context)``); the twin
        destroys it at :meth:`close`. An exception its callbacks raise ends the harness's
        wait with that exception.

        :return: the node
        """
        self._acting('add_node()').executor.add_node(node)
        self._nodes.append(node)
        return node

    def start_controller(self, args: Sequence[str], *,
                         env: Optional[Mapping[str, str]] = None,
                         pace: Optional[str] = None) -> subprocess.Popen:
        """Start a controller as its own process in the twin's domain (loopback discovery);
        it is stopped (SIGINT, SIGTERM, SIGKILL) at :meth:`close`. If it ends with a non-zero
        exit code (or by a signal) before, the next call that drives the twin raises
        :class:`~conveyor_twin.health.BackgroundFailure` naming it, its exit code and the end
        of its output.

        :param args: command line, e.g. ``[sys.executable, 'my_controller.py']``
        :param env: more environment variables
        :param pace: the name of the controller's node, if it acknowledges what it read on
            ``lockstep_ack`` (:mod:`conveyor_twin.testing.pacing`): after every chunk the
            harness then waits until it acknowledged the chunk's last stamp and the twin
            answered the commands it sent before; None: not paced
        :return: the process; its output is in :meth:`controller_output`
        """
        if pace is not None and (not isinstance(pace, str) or not pace):
            raise ValueError(f'pace = {pace!r} is not allowed: it must be the name of the '
                             "controller's node or None")
        driver = self._acting('start_controller()')
        return self._supervisor.start(args, env, pace or '', driver).process

    def controller_output(self, index: int = 0) -> str:
        """Return what a started controller has printed so far (stdout and stderr).

        :param index: the controller's number in the order started (from 0)
        """
        self._check_open('controller_output()')
        count = len(self._supervisor.controllers)
        if count:
            checks.integer('controller_output(index): index', index, 0, count - 1)
        return self._supervisor.output(index)

    def wait_for_node(self, name: str, *, subscribes: Sequence[str] = (),
                      publishes: Sequence[str] = (), timeout: Optional[float] = None) -> None:
        """Wait until a node (e.g. a started controller) is discovered with the subscriptions
        and publishers given (topic names relative to the twin, e.g. ``'light_barriers'``).

        :param timeout: longest wait [s] (> 0; default: the harness's timeout)
        :raises ConditionNotMet: when it is not, or a started controller exits meanwhile; the
            message carries the controllers' output
        """
        timeout = checks.seconds('wait_for_node: timeout', timeout, open_low=True,
                                 optional=True)
        driver = self._check_open('wait_for_node()')
        probe = driver.probe
        controllers = self._supervisor.controllers

        def endpoints(infos: Any) -> bool:
            return any(i.node_name == name for i in infos)

        def ready() -> bool:
            if any(c.process.poll() is not None for c in controllers):
                return True
            return (all(endpoints(probe.get_subscriptions_info_by_topic(_abs(t)))
                        for t in subscribes)
                    and all(endpoints(probe.get_publishers_info_by_topic(_abs(t)))
                            for t in publishes)
                    and name in probe.get_node_names())

        limit = driver.timeout if timeout is None else timeout
        with self._failing():
            if not wait_for(ready, limit, driver.executor):
                raise ConditionNotMet(f'node {name!r} discovered: not met within {limit:g} s'
                                      + self._supervisor.report())
            if any(c.process.poll() is not None for c in controllers):
                raise ConditionNotMet(f'node {name!r}: a controller process exited before it '
                                      f'was discovered{self._supervisor.report()}')


def _abs(topic: str) -> str:
    return topic if topic.startswith('/') else '/' + topic
