"""The contract table as rclpy endpoints: every type importable, names and QoS as the table."""

import pytest

from conveyor_twin import contract

pytestmark = pytest.mark.ros


@pytest.mark.parametrize('entry', list(contract.CONTRACT.values()), ids=lambda t: t.name)
def test_every_entry_type_is_an_installed_interface(entry):
    from conveyor_twin.ros.endpoints import message_class
    cls = message_class(entry.type_name)
    if entry.kind is contract.Kind.SERVICE:
        assert hasattr(cls, 'Request') and hasattr(cls, 'Response')
    elif entry.stamp is contract.Stamp.HEADER:  # the stamp is the first field
        assert list(cls.get_fields_and_field_types())[0] == 'header'
    elif entry.stamp is contract.Stamp.CLOCK:
        assert list(cls.get_fields_and_field_types()) == ['clock']


def test_stream_publishers_follow_the_table(ros_context):
    from rclpy.node import Node

    from conveyor_twin.ros.endpoints import create_publisher, create_service, \
        create_subscription
    from conveyor_twin.ros.qos import to_rclpy
    node = Node('endpoints_probe', context=ros_context, namespace='/twin')
    try:
        for topic in contract.STREAMS:
            pub = create_publisher(node, topic)
            expected = '/clock' if topic is contract.CLOCK else '/twin/' + topic.name
            assert pub.topic_name == expected
            assert pub.qos_profile == to_rclpy(topic.qos)
        for topic in contract.COMMANDS:
            sub = create_subscription(node, topic, lambda _msg: None)
            assert sub.topic_name == '/twin/' + topic.name
        for service in contract.SERVICES:
            assert create_service(node, service, lambda req, resp: resp).srv_name == \
                service.name
        with pytest.raises(ValueError, match='not a stream'):
            create_publisher(node, contract.BELT_COMMAND)
    finally:
        node.destroy_node()
