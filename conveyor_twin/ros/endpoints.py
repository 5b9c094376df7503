"""The contract table as rclpy endpoints: publishers, subscriptions and services by entry.

Every node creates its endpoints of the ROS interface through these functions from the
entries of :mod:`conveyor_twin.contract`, so name, type and QoS are written once.
"""

import importlib
from typing import Any, Callable

from conveyor_twin.contract import Kind, Topic
from conveyor_twin.ros.qos import to_rclpy


def message_class(type_name: str) -> Any:
    """Return the generated Python class of ``pkg/msg/Type`` or ``pkg/srv/Type``.

    :raises ImportError: naming the type if its interface package is not installed.
    """
    package, kind, name = type_name.split('/')
    try:
        return getattr(importlib.import_module(f'{package}.{kind}'), name)
    except (ImportError, AttributeError) as err:
        raise ImportError(f'message type {type_name} is not available: {err}') from None


def create_publisher(node: Any, topic: Topic) -> Any:
    """Create the publisher of a contract stream on ``node`` (its type and QoS)."""
    if topic.kind is not Kind.STREAM:
        raise ValueError(f'{topic.name} is a {topic.kind.value}, not a stream')
    return node.create_publisher(message_class(topic.type_name), topic.name, to_rclpy(topic.qos))


def create_subscription(node: Any, topic: Topic, callback: Callable[[Any], None], *,
                        raw: bool = False) -> Any:
    """Create a subscription to a contract topic on ``node`` (its type and QoS).

    :param raw: take CDR bytes instead of message objects.
    """
    if topic.kind is Kind.SERVICE:
        raise ValueError(f'{topic.name} is a service, not a topic')
    return node.create_subscription(message_class(topic.type_name), topic.name, callback,
                                    to_rclpy(topic.qos), raw=raw)


def create_service(node: Any, topic: Topic, callback: Callable[[Any, Any], Any]) -> Any:
    """Create the server of a contract service on ``node``."""
    if topic.kind is not Kind.SERVICE:
        raise ValueError(f'{topic.name} is a {topic.kind.value}, not a service')
    return node.create_service(message_class(topic.type_name), topic.name, callback)
