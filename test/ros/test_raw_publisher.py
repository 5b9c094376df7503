"""A publish the middleware refuses is counted and logged, never raised into the step."""

from rclpy._rclpy_pybind11 import RCLError

from conveyor_twin.ros.qos import publish_failures, raw_publish, RawPublisher


class _Handle:
    def __init__(self, refuse):
        self.refuse = refuse
        self.sent = []

    def publish_raw(self, data):
        if data in self.refuse:
            raise RCLError('Failed to publish: cannot publish data')
        self.sent.append(data)


class _Publisher:
    topic_name = '/parts'

    def __init__(self, refuse=()):
        self.handle = _Handle(set(refuse))


class _Logger:
    def __init__(self):
        self.lines = []

    def warning(self, text):
        self.lines.append(text)


class _Node:
    def __init__(self, *publishers):
        for i, p in enumerate(publishers):
            setattr(self, f'_pub{i}', p)
        self.other = object()


def test_refused_publish_is_counted_and_logged_once_per_thousand():
    logger = _Logger()
    publisher = _Publisher(refuse={b'b'})
    pub = raw_publish(publisher, logger)
    for data in [b'a', b'b', b'c'] + [b'b'] * 1000:
        pub(data)
    assert publisher.handle.sent == [b'a', b'c']
    assert pub.failures == 1001
    assert len(logger.lines) == 2 and '/parts' in logger.lines[0]
    assert 'cannot publish data' in logger.lines[0]


def test_other_errors_still_raise():
    class Broken(_Publisher):
        def __init__(self):
            super().__init__()
            self.handle.publish_raw = lambda data: (_ for _ in ()).throw(TypeError('bytes'))
    pub = RawPublisher(Broken())
    try:
        pub('not bytes')
    except TypeError:
        pass
    else:
        raise AssertionError('a programming error must not be swallowed')
    assert pub.failures == 0


def test_publish_failures_sums_a_nodes_raw_publishers():
    a, b = raw_publish(_Publisher(refuse={b'x'})), raw_publish(_Publisher(refuse={b'x'}))
    node = _Node(a, b)
    a(b'x'), a(b'x'), b(b'x'), b(b'ok')
    assert publish_failures(node) == 3
