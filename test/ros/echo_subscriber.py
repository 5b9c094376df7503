"""Child process of the contract tests: receive messages of one type and print them back as CDR.

Usage: ``python echo_subscriber.py <pkg>/msg/<Type> <topic> <count> <timeout [s]>``

Prints ``READY`` once a publisher has matched its subscription, then, for each of ``count``
received messages (deserialized into the generated class by this process), one line with the
message serialized again, in hex. Exits 0 after ``count`` messages, 1 on timeout. Run it in the
test's ROS environment (``ros_subprocess_env``).
"""

import importlib
import sys
import time
from typing import List


def main(argv: List[str]) -> int:
    """Run the echo subscriber; return the exit code."""
    type_name, topic, count, timeout = argv[0], argv[1], int(argv[2]), float(argv[3])
    package, kind, name = type_name.split('/')
    msg_type = getattr(importlib.import_module(f'{package}.{kind}'), name)

    import rclpy
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.serialization import serialize_message

    rclpy.init()
    node = rclpy.create_node('contract_echo_subscriber')
    received: List[object] = []
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                     reliability=ReliabilityPolicy.RELIABLE)
    subscription = node.create_subscription(msg_type, topic, received.append, qos)
    deadline = time.monotonic() + timeout
    ready = False
    printed = 0
    try:
        while printed < count and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.01)
            if not ready and subscription.get_publisher_count() > 0:
                print('READY', flush=True)
                ready = True
            while printed < len(received):
                print(serialize_message(received[printed]).hex(), flush=True)
                printed += 1
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0 if printed >= count else 1


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
