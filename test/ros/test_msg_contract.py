"""The generated conveyor_twin_msgs types against the ROS interface contract (architecture.md).

(a) every message and service has exactly the contract's fields, types and order;
(b) every message crosses a real publisher/subscriber intact, in one process and (PartStates) to a
    subscriber in another process;
(c) every service crosses a real server/client intact.
"""

import array
import importlib
from pathlib import Path
import queue
import subprocess
import sys
import threading
from typing import Any, Dict, List, Tuple

import numpy as np
import pytest

from conveyor_twin.testing import wait_for

pytestmark = pytest.mark.ros

MSGS = importlib.import_module('conveyor_twin_msgs.msg')
SRVS = importlib.import_module('conveyor_twin_msgs.srv')

# The contract as written in architecture.md ("Message fields"), in .msg notation and order.
CONTRACT_MSGS: Dict[str, List[Tuple[str, str]]] = {
    'PartStates': [
        ('header', 'std_msgs/Header'), ('step', 'uint64'), ('id', 'uint32[]'),
        ('part_type', 'uint16[]'), ('x', 'float64[]'), ('y', 'float64[]'),
        ('yaw', 'float64[]'), ('vx', 'float64[]'), ('vy', 'float64[]'), ('wz', 'float64[]'),
    ],
    'DensityGrid': [
        ('header', 'std_msgs/Header'), ('step', 'uint64'), ('zone', 'string'),
        ('origin_x', 'float64'), ('origin_y', 'float64'), ('resolution', 'float64'),
        ('nx', 'uint32'), ('ny', 'uint32'), ('density', 'float32[]'),
        ('total_parts', 'float64'),
    ],
    'LightBarrierStates': [
        ('header', 'std_msgs/Header'), ('step', 'uint64'), ('name', 'string[]'),
        ('blocked', 'bool[]'), ('edge_count', 'uint32[]'),
    ],
    'LightBarrierEdge': [
        ('header', 'std_msgs/Header'), ('name', 'string'), ('blocked', 'bool'),
        ('part_id', 'uint32'),
    ],
    'BeltCommand': [('belt', 'string'), ('speed', 'float64'), ('sender', 'string'),
                    ('sequence', 'uint32')],
    'BeltStates': [
        ('header', 'std_msgs/Header'), ('name', 'string[]'), ('commanded_speed', 'float64[]'),
        ('speed', 'float64[]'),
    ],
    'ActuatorCommand': [('actuator', 'string'), ('position', 'float64'), ('sender', 'string'),
                        ('sequence', 'uint32')],
    'ActuatorStates': [
        ('header', 'std_msgs/Header'), ('name', 'string[]'),
        ('commanded_position', 'float64[]'), ('position', 'float64[]'),
        ('stalled', 'bool[]'), ('load', 'float64[]'),
    ],
    # the faults interface (docs/faults.md), beyond architecture.md's list
    'FaultState': [
        ('header', 'std_msgs/Header'), ('id', 'uint32[]'), ('kind', 'string[]'),
        ('target', 'string[]'), ('param_count', 'uint32[]'), ('param_name', 'string[]'),
        ('param_value', 'float64[]'), ('part_type', 'string[]'), ('duration', 'float64[]'),
        ('since', 'float64[]'), ('injected', 'uint32[]'), ('cleared', 'uint32[]'),
        ('cleared_reason', 'string[]'), ('total_injected', 'uint32'),
        ('total_rejected', 'uint32'),
    ],
    # the plant's link and progress messages (docs/plant.md), beyond architecture.md's list
    'PartTransfer': [
        ('header', 'std_msgs/Header'), ('link', 'string'), ('through', 'uint64'),
        ('first_seq', 'uint64'), ('held_from', 'uint64'), ('run', 'uint64'),
        ('step_left', 'uint64[]'), ('id', 'uint32[]'), ('origin_id', 'uint32[]'),
        ('part_type', 'uint16[]'), ('x', 'float64[]'), ('y', 'float64[]'), ('yaw', 'float64[]'),
        ('vx', 'float64[]'), ('vy', 'float64[]'), ('wz', 'float64[]'),
    ],
    'TransferAccepted': [
        ('header', 'std_msgs/Header'), ('link', 'string'), ('through', 'uint64'),
        ('run', 'uint64'), ('starting', 'bool'), ('exit_run', 'uint64'),
        ('exit_run_known', 'bool'), ('final', 'bool'), ('seq', 'uint64[]'), ('step', 'uint64[]'),
    ],
    'CellProgress': [
        ('header', 'std_msgs/Header'), ('cell', 'string'), ('step', 'uint64'),
        ('end_step', 'uint64'), ('done', 'bool'), ('run', 'uint64'), ('entered', 'float64'),
        ('in_cell', 'float64'), ('left', 'float64'), ('vanished', 'float64'),
        ('exit_link', 'string[]'), ('exit_sent', 'uint64[]'), ('exit_accepted', 'uint64[]'),
        ('exit_resent', 'uint64[]'), ('entry_link', 'string[]'), ('entry_inserted', 'uint64[]'),
        ('entry_waiting', 'uint64[]'), ('entry_earlier', 'uint64[]'),
        ('entry_dropped', 'uint64[]'), ('step_time_mean_ms', 'float64'),
        ('real_time_factor', 'float64'), ('state_hash', 'string'),
    ],
}
CONTRACT_SRVS: Dict[str, Tuple[List[Tuple[str, str]], List[Tuple[str, str]]]] = {
    'Step': (
        [('steps', 'uint32')],
        [('step', 'uint64'), ('stamp', 'builtin_interfaces/Time')],
    ),
    'Reset': (
        [('cell_file', 'string'), ('seed', 'uint64')],
        [('success', 'bool'), ('message', 'string')],
    ),
    'SpawnParts': (
        [('part_type', 'string'), ('x', 'float64[]'), ('y', 'float64[]'), ('yaw', 'float64[]')],
        [('success', 'bool'), ('message', 'string'), ('id', 'uint32[]')],
    ),
    'InjectFault': (
        [('kind', 'string'), ('target', 'string'), ('param_names', 'string[]'),
         ('param_values', 'float64[]'), ('duration', 'float64'), ('part_type', 'string')],
        [('success', 'bool'), ('message', 'string'), ('id', 'uint32')],
    ),
    'ClearFault': (
        [('id', 'uint32')],
        [('success', 'bool'), ('message', 'string')],
    ),
}

# .msg primitive names -> the names rosidl_generator_py reports.
_ROSIDL_NAMES = {'float64': 'double', 'float32': 'float', 'bool': 'boolean'}
_INT_BITS = {'int8': 8, 'uint8': 8, 'int16': 16, 'uint16': 16, 'int32': 32, 'uint32': 32,
             'int64': 64, 'uint64': 64}
# Reliable, keep-last 100: the contract's QoS of the streams.
CONTRACT_DEPTH = 100
DISCOVERY_TIMEOUT = 20.0  # matching publisher and subscriber in one process [s]
DELIVERY_TIMEOUT = 20.0  # a few messages or a service call [s]
CHILD_TIMEOUT = 60.0  # a child process: interpreter start, discovery, delivery [s]
ECHO_SCRIPT = Path(__file__).with_name('echo_subscriber.py')


def rosidl_type(contract_type: str) -> str:
    """Translate a .msg field type into what ``get_fields_and_field_types`` reports.

    :param contract_type: e.g. ``float64[]``, ``std_msgs/Header``
    :return: e.g. ``sequence<double>``, ``std_msgs/Header``
    """
    if contract_type.endswith('[]'):
        return f'sequence<{rosidl_type(contract_type[:-2])}>'
    return _ROSIDL_NAMES.get(contract_type, contract_type)


def _qos() -> Any:
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=CONTRACT_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE)


def _sample(field_type: str, rng: np.random.Generator, n: int) -> Any:
    """Return a non-default value of a rosidl field type (sequences get ``n`` elements)."""
    if field_type.startswith('sequence<'):
        element = field_type[len('sequence<'):-1]
        if element == 'boolean':
            return [bool(i % 3 != 1) for i in range(n)]
        if element == 'string':
            return [f'item-{i}-\u00e4\u20ac' for i in range(n)]
        return [_sample(element, rng, 0) for _ in range(n)]
    if field_type == 'std_msgs/Header':
        from std_msgs.msg import Header

        return Header(stamp=_sample('builtin_interfaces/Time', rng, n), frame_id='cell')
    if field_type == 'builtin_interfaces/Time':
        from builtin_interfaces.msg import Time

        return Time(sec=int(rng.integers(1, 2**31 - 1)), nanosec=int(rng.integers(1, 10**9)))
    if field_type in _INT_BITS:
        bits = _INT_BITS[field_type]
        low, high = (1, 2**bits - 1) if field_type.startswith('u') else (-2**(bits - 1), -1)
        # Near the top of the range: exercises the high bits; never the default 0.
        return int(high - int(rng.integers(0, 2**min(bits - 2, 30))))
    if field_type == 'double':
        return float(rng.normal() * 1e3) or 0.5
    if field_type == 'float':
        return float(np.float32(rng.normal() * 1e3)) or 0.5
    if field_type == 'boolean':
        return True
    if field_type == 'string':
        return 'conveyor \u00e4\u20ac/zone_1'
    raise AssertionError(f'no sample for field type {field_type}')


def populated(msg_class: Any, seed: int, n: int) -> Any:
    """Return an instance of a generated class with every field set to a non-default value.

    :param msg_class: generated message, request or response class
    :param seed: random seed of the values
    :param n: length of every sequence
    :return: the populated message
    """
    rng = np.random.default_rng(seed)
    msg = msg_class()
    for name, field_type in msg_class.get_fields_and_field_types().items():
        setattr(msg, name, _sample(field_type, rng, n))
    return msg


def plain(value: Any) -> Any:
    """Convert a message (recursively) into dicts, lists and Python scalars, for comparison."""
    if hasattr(value, 'get_fields_and_field_types'):
        return {name: plain(getattr(value, name)) for name in value.get_fields_and_field_types()}
    if isinstance(value, (array.array, np.ndarray)):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [plain(item) for item in value]
    return value


def assert_fully_populated(msg: Any) -> None:
    """Fail when a field of ``msg`` still has its default value (the test would prove nothing)."""
    default = plain(type(msg)())
    for name, value in plain(msg).items():
        assert value != default[name], f'{type(msg).__name__}.{name} is not populated'


# (a) -------------------------------------------------------------------------------------------

@pytest.mark.smoke
@pytest.mark.parametrize('name', sorted(CONTRACT_MSGS))
def test_message_fields_match_contract(name: str) -> None:
    msg_class = getattr(MSGS, name)
    expected = [(field, rosidl_type(kind)) for field, kind in CONTRACT_MSGS[name]]
    assert list(msg_class.get_fields_and_field_types().items()) == expected


@pytest.mark.parametrize('name', sorted(CONTRACT_SRVS))
def test_service_fields_match_contract(name: str) -> None:
    srv_class = getattr(SRVS, name)
    request, response = CONTRACT_SRVS[name]
    assert list(srv_class.Request.get_fields_and_field_types().items()) == [
        (field, rosidl_type(kind)) for field, kind in request]
    assert list(srv_class.Response.get_fields_and_field_types().items()) == [
        (field, rosidl_type(kind)) for field, kind in response]


def test_contract_covers_every_generated_type() -> None:
    generated_msgs = {name for name in dir(MSGS)
                      if hasattr(getattr(MSGS, name), 'get_fields_and_field_types')}
    generated_srvs = {name for name in dir(SRVS) if hasattr(getattr(SRVS, name), 'Request')}
    assert generated_msgs == set(CONTRACT_MSGS)
    assert generated_srvs == set(CONTRACT_SRVS)


# (b) -------------------------------------------------------------------------------------------

@pytest.mark.smoke
@pytest.mark.parametrize('name', sorted(CONTRACT_MSGS))
def test_message_round_trip_in_process(name: str, ros_executor: Any) -> None:
    from rclpy.node import Node

    msg_class = getattr(MSGS, name)
    context = ros_executor.context
    topic = f'contract_{name}'
    sent = [populated(msg_class, seed, n) for seed, n in ((1, 1), (2, 257), (3, 5))]
    for msg in sent:
        assert_fully_populated(msg)
    received: List[Any] = []
    pub_node = Node('contract_publisher', context=context)
    sub_node = Node('contract_subscriber', context=context)
    ros_executor.add_node(pub_node)
    ros_executor.add_node(sub_node)
    publisher = pub_node.create_publisher(msg_class, topic, _qos())
    subscription = sub_node.create_subscription(msg_class, topic, received.append, _qos())
    assert wait_for(lambda: publisher.get_subscription_count() == 1
                    and subscription.get_publisher_count() == 1, DISCOVERY_TIMEOUT, ros_executor)

    for msg in sent:
        publisher.publish(msg)
    assert wait_for(lambda: len(received) >= len(sent), DELIVERY_TIMEOUT, ros_executor)

    assert len(received) == len(sent)
    for got, msg in zip(received, sent):
        assert isinstance(got, msg_class)
        assert plain(got) == plain(msg)


def _read_lines(stream: Any, lines: 'queue.Queue[str]') -> None:
    for line in stream:
        lines.put(line.strip())


@pytest.mark.smoke
@pytest.mark.slow
def test_part_states_reach_another_process(ros_executor: Any, ros_processes: Any,
                                           tmp_path: Path) -> None:
    from rclpy.node import Node
    from rclpy.serialization import deserialize_message

    topic = 'contract_parts_cross_process'
    sent = [populated(MSGS.PartStates, seed, n) for seed, n in ((11, 1000), (12, 3))]
    for msg in sent:
        assert_fully_populated(msg)
    log = tmp_path / 'echo_subscriber.log'
    with open(log, 'w') as stderr:
        child = ros_processes.start(
            [sys.executable, str(ECHO_SCRIPT), 'conveyor_twin_msgs/msg/PartStates', topic,
             str(len(sent)), str(CHILD_TIMEOUT)],
            stdout=subprocess.PIPE, stderr=stderr, text=True)
    lines: 'queue.Queue[str]' = queue.Queue()
    threading.Thread(target=_read_lines, args=(child.stdout, lines), daemon=True).start()
    output: List[str] = []

    def drained() -> List[str]:
        while not lines.empty():
            output.append(lines.get_nowait())
        return output

    def child_failed(what: str) -> str:
        return f'{what}; child exit code {child.poll()}, stdout {drained()}, ' \
               f'stderr {log.read_text()!r}'

    node = Node('contract_cross_publisher', context=ros_executor.context)
    ros_executor.add_node(node)
    publisher = node.create_publisher(MSGS.PartStates, topic, _qos())
    matched = wait_for(lambda: 'READY' in drained() and publisher.get_subscription_count() == 1
                       or child.poll() is not None, CHILD_TIMEOUT, ros_executor)
    assert matched and child.poll() is None, child_failed('no match with the child')

    for msg in sent:
        publisher.publish(msg)
    assert wait_for(lambda: len(drained()) > len(sent) or child.poll() is not None,
                    CHILD_TIMEOUT, ros_executor), child_failed('not every message came back')
    assert child.wait(timeout=CHILD_TIMEOUT) == 0, child_failed('the child failed')
    echoed = drained()[1:]
    assert len(echoed) == len(sent), child_failed('wrong number of messages')
    for line, msg in zip(echoed, sent):
        assert plain(deserialize_message(bytes.fromhex(line), MSGS.PartStates)) == plain(msg)


# (c) -------------------------------------------------------------------------------------------

@pytest.mark.smoke
@pytest.mark.parametrize('name', sorted(CONTRACT_SRVS))
def test_service_round_trip(name: str, ros_executor: Any) -> None:
    from rclpy.node import Node

    srv_class = getattr(SRVS, name)
    context = ros_executor.context
    request = populated(srv_class.Request, 21, 17)
    response = populated(srv_class.Response, 22, 9)
    assert_fully_populated(request)
    assert_fully_populated(response)
    served: List[Any] = []

    def handle(got: Any, answer: Any) -> Any:
        served.append(got)
        for field in srv_class.Response.get_fields_and_field_types():
            setattr(answer, field, getattr(response, field))
        return answer

    server_node = Node('contract_server', context=context)
    client_node = Node('contract_client', context=context)
    ros_executor.add_node(server_node)
    ros_executor.add_node(client_node)
    server_node.create_service(srv_class, f'contract_{name}', handle)
    client = client_node.create_client(srv_class, f'contract_{name}')
    assert wait_for(client.service_is_ready, DISCOVERY_TIMEOUT, ros_executor)

    future = client.call_async(request)
    ros_executor.spin_until_future_complete(future, timeout_sec=DELIVERY_TIMEOUT)

    assert future.done(), f'no answer from the {name} service within {DELIVERY_TIMEOUT} s'
    assert len(served) == 1 and plain(served[0]) == plain(request)
    assert plain(future.result()) == plain(response)
