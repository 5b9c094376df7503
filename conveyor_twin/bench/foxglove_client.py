"""A Foxglove client for ``bench twin --foxglove``: subscribes to every channel and reads all.

``python -m conveyor_twin.bench.foxglove_client PORT`` connects to the twin's Foxglove view
(retrying until it listens), subscribes to every advertised channel, reads until SIGINT or
SIGTERM and prints one line ``foxglove client: {json}`` with the messages and bytes per topic.
A plain WebSocket client (``websockets``), as a viewer would connect.
"""

import json
import signal
import struct
import sys
import time
from typing import Dict, List

RESULT_PREFIX = 'foxglove client: '
SUBPROTOCOL = 'foxglove.sdk.v1'
CONNECT_TIMEOUT = 60.0  # s


def main(argv: List[str]) -> int:
    """Read every channel of the view at ``127.0.0.1:argv[0]`` until signalled."""
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect

    port = int(argv[0])
    stop: List[bool] = []
    signal.signal(signal.SIGINT, lambda *_: stop.append(True))
    signal.signal(signal.SIGTERM, lambda *_: stop.append(True))
    deadline = time.monotonic() + CONNECT_TIMEOUT
    while True:
        try:
            ws = connect(f'ws://127.0.0.1:{port}', subprotocols=[SUBPROTOCOL], max_size=None)
            break
        except OSError:
            if time.monotonic() > deadline or stop:
                print(RESULT_PREFIX + json.dumps({'error': f'no view at port {port}'}),
                      flush=True)
                return 1
            time.sleep(0.1)
    topics: Dict[int, str] = {}  # subscription id -> topic
    channels = set()
    counts: Dict[str, int] = {}
    volume = 0
    with ws:
        while not stop:
            try:
                message = ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            except ConnectionClosed:
                break
            if isinstance(message, str):
                data = json.loads(message)
                if data.get('op') == 'advertise':
                    new = [c for c in data['channels'] if c['id'] not in channels]
                    channels.update(c['id'] for c in new)
                    subscriptions = [{'id': len(topics) + i + 1, 'channelId': c['id']}
                                     for i, c in enumerate(new)]
                    topics.update({s['id']: c['topic'] for s, c in zip(subscriptions, new)})
                    ws.send(json.dumps({'op': 'subscribe', 'subscriptions': subscriptions}))
                continue
            if message[0] == 1:
                subscription, = struct.unpack_from('<I', message, 1)
                topic = topics.get(subscription, '?')
                counts[topic] = counts.get(topic, 0) + 1
                volume += len(message)
    print(RESULT_PREFIX + json.dumps({'messages': counts, 'bytes': volume}), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
