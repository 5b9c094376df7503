"""Drive a running twin (composed in this process or split over processes) like a controller.

A :class:`Driver` owns a probe node and its own executor; it calls ``step`` in chunks and waits
until every reliable stream has delivered each chunk, sends commands and waits until the twin
acknowledged them, and spawns parts. It knows nothing of the layout it talks to.
"""

from typing import Dict

from conveyor_twin_msgs.msg import ActuatorCommand, BeltCommand
from conveyor_twin_msgs.srv import Reset, SpawnParts, Step
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor

from conveyor_twin.ros.qos import COMMAND_QOS
from conveyor_twin.wire import cdr
from test.ros.probe import Probe
from test.ros_env import wait_for

TIMEOUT = 60.0
EVERY_STEP = ('parts', 'light_barriers', 'belt_states', 'actuator_states')
HASHED = ('parts', 'density', 'light_barriers', 'light_barrier_edges', 'belt_states',
          'actuator_states')


class Driver:
    """A probe, clients and command publishers in one executor, against a twin's namespace.

    :param context: rclpy context.
    :param density_per_step: density messages per step (one per macro zone of the cell).
    """

    def __init__(self, context, *, density_per_step: int = 0, name: str = 'probe') -> None:
        self.density_per_step = density_per_step
        self.probe = Probe(context, name=name)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.probe)
        self.step_client = self.probe.create_client(Step, 'step')
        self.spawn_client = self.probe.create_client(SpawnParts, 'spawn_parts')
        self.reset_client = self.probe.create_client(Reset, 'reset')
        self.belt_pub = self.probe.create_publisher(BeltCommand, 'belt_command', COMMAND_QOS)
        self.actuator_pub = self.probe.create_publisher(ActuatorCommand, 'actuator_command',
                                                        COMMAND_QOS)

    def wait_connected(self, timeout: float = TIMEOUT) -> bool:
        """Wait until every stream, service and command topic of the twin is matched."""
        return wait_for(lambda: self.probe.matched() and self.step_client.service_is_ready()
                        and self.spawn_client.service_is_ready()
                        and self.belt_pub.get_subscription_count() > 0
                        and self.actuator_pub.get_subscription_count() > 0
                        and all(s.get_publisher_count() > 0 for s in self.probe._subs
                                if s.topic_name != '/clock'),
                        timeout, self.executor)

    def call(self, client, request):
        """Call a service and return its response (bounded wait)."""
        future = client.call_async(request)
        self.executor.spin_until_future_complete(future, timeout_sec=TIMEOUT)
        assert future.done(), 'service call timed out'
        return future.result()

    def step(self, n: int, chunk: int = 50) -> Step.Response:
        """Advance n steps in calls of at most ``chunk``; wait for every stream after each."""
        response = None
        while n > 0:
            k = min(n, chunk)
            before = self.counts()
            response = self.call(self.step_client, Step.Request(steps=k))
            want = {t: before[t] + k for t in EVERY_STEP}
            want['density'] = before['density'] + k * self.density_per_step
            assert wait_for(lambda: all(len(self.probe.received[t]) >= c
                                        for t, c in want.items()),
                            TIMEOUT, self.executor), ('streams incomplete', self.counts(), want)
            n -= k
        return response

    def counts(self) -> Dict[str, int]:
        """Messages received so far per topic."""
        return {t: len(v) for t, v in self.probe.received.items()}

    def command(self, msg) -> None:
        """Publish a belt or actuator command and wait until the twin acknowledged it."""
        publisher = self.belt_pub if isinstance(msg, BeltCommand) else self.actuator_pub
        publisher.publish(msg)
        assert publisher.wait_for_all_acked(Duration(seconds=TIMEOUT))

    def spawn(self, part_type: str, x, y, yaw) -> SpawnParts.Response:
        """Place parts through the ``spawn_parts`` service."""
        response = self.call(self.spawn_client, SpawnParts.Request(
            part_type=part_type, x=list(x), y=list(y), yaw=list(yaw)))
        assert response.success, response.message
        return response

    def settle_edges(self) -> None:
        """Wait until every edge counted in the last barrier state has arrived."""
        last = self.probe.received['light_barriers'][-1]
        total = int(sum(cdr.decode_light_barrier_states(last)[5]))
        assert wait_for(lambda: len(self.probe.received['light_barrier_edges']) >= total,
                        TIMEOUT, self.executor), 'light-barrier edges missing'

    def run(self, sequence) -> None:
        """Play a sequence of ``('step', n)``, ``('command', msg)``, ``('spawn', args)``."""
        for kind, arg in sequence:
            if kind == 'step':
                self.step(arg)
            elif kind == 'command':
                self.command(arg)
            elif kind == 'spawn':
                self.spawn(*arg)
            else:
                raise ValueError(f'unknown sequence item {kind!r}')
        self.settle_edges()

    def digests(self) -> Dict[str, str]:
        """SHA-256 of every hashed stream (everything but the best-effort /clock)."""
        return {t: self.probe.digest(t) for t in HASHED}

    def parameters(self, node_name: str) -> Dict[str, tuple]:
        """List, describe and get a node's parameters through its parameter services (as
        ``ros2 param dump``/``describe`` do); return ``{name: (value, description, read_only)}``.
        """
        from rclpy.parameter import parameter_value_to_python
        from rclpy.parameter_client import AsyncParameterClient

        client = AsyncParameterClient(self.probe, node_name)
        assert wait_for(client.services_are_ready, TIMEOUT, self.executor), node_name

        def result(future):
            self.executor.spin_until_future_complete(future, timeout_sec=TIMEOUT)
            assert future.done(), f'parameter service of {node_name} timed out'
            return future.result()

        names = list(result(client.list_parameters()).result.names)
        names = [n for n in names if n != 'use_sim_time']
        values = result(client.get_parameters(names)).values
        descriptors = result(client.describe_parameters(names)).descriptors
        return {n: (parameter_value_to_python(v), d.description, d.read_only)
                for n, v, d in zip(names, values, descriptors)}

    def close(self) -> None:
        """Destroy the probe and the executor."""
        self.executor.remove_node(self.probe)
        self.probe.destroy_node()
        self.executor.shutdown(timeout_sec=5.0)
