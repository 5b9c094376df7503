"""The reader handshake: a writer answers only once it reaches the reader's node."""

from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
import pytest

from conveyor_twin.ros.reader_handshake import HandshakeReader, HandshakeResponder
from conveyor_twin.testing import wait_for

pytestmark = pytest.mark.ros
TOPIC = '/handshake_stream'
VOLATILE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
LATCHED = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


def _spin(executor, seconds: float) -> None:
    wait_for(lambda: False, seconds, executor)


def test_a_writer_answers_the_hello_once_its_writers_reach_the_readers_node(ros_context):
    writer = Node('handshake_writer', context=ros_context)
    reader = Node('handshake_reader', context=ros_context)
    other = Node('handshake_other', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    for node in (writer, reader, other):
        executor.add_node(node)
    try:
        HandshakeResponder(writer)  # before its publisher: publishers are looked at later
        writer.create_publisher(String, TOPIC, VOLATILE)
        handshake = HandshakeReader(reader, [TOPIC])
        # An incompatible reader (asks for latched history a volatile writer never offers)
        # and a compatible one of another node: neither stands for the hello's reader.
        other.create_subscription(String, TOPIC, lambda m: None, LATCHED)
        other.create_subscription(String, TOPIC, lambda m: None, VOLATILE)
        _spin(executor, 0.5)
        assert handshake.writers() == {'/handshake_writer'}
        assert not handshake.reached()  # the hello's node reads nothing yet
        reader.create_subscription(String, TOPIC, lambda m: None, VOLATILE)
        assert wait_for(handshake.reached, 10.0, executor)
        assert handshake.answered == {'/handshake_writer'}
    finally:
        executor.shutdown()
        for node in (writer, reader, other):
            node.destroy_node()


def test_a_writer_without_a_responder_keeps_the_reader_waiting(ros_context):
    silent = Node('handshake_silent', context=ros_context)
    reader = Node('handshake_reader2', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    for node in (silent, reader):
        executor.add_node(node)
    try:
        silent.create_publisher(String, TOPIC + '2', VOLATILE)
        reader.create_subscription(String, TOPIC + '2', lambda m: None, VOLATILE)
        handshake = HandshakeReader(reader, [TOPIC + '2'])
        assert wait_for(lambda: handshake.writers() == {'/handshake_silent'}, 10.0, executor)
        _spin(executor, 0.5)
        assert not handshake.reached()
    finally:
        executor.shutdown()
        for node in (silent, reader):
            node.destroy_node()
