"""``conveyor-twin bench WHAT``: benchmarks that print figures and ratios (not tests)."""

import importlib
import sys
from typing import List

# what -> module with ``main(argv: List[str]) -> int``
BENCHES = {
    'micro': 'conveyor_twin.bench.micro',
    'clog': 'conveyor_twin.bench.clog',
    'curve': 'conveyor_twin.bench.curve',
    'macro': 'conveyor_twin.bench.macro',
    'record': 'conveyor_twin.bench.record',
    'twin': 'conveyor_twin.bench.twin',
    'scale': 'conveyor_twin.bench.scale',
    'host': 'conveyor_twin.bench.host',
    'soak': 'conveyor_twin.bench.soak',
    'testing': 'conveyor_twin.bench.testing',
    'plant': 'conveyor_twin.bench.plant',
    'plc': 'conveyor_twin.bench.plc',
}


def main(argv: List[str]) -> int:
    """Run the benchmark named by ``argv[0]`` with the remaining arguments."""
    if not argv or argv[0] in ('-h', '--help') or argv[0] not in BENCHES:
        print('usage: conveyor-twin bench {' + ','.join(BENCHES) + '} [--json] [options]',
              file=sys.stderr if argv and argv[0] not in ('-h', '--help') else sys.stdout)
        return 0 if argv and argv[0] in ('-h', '--help') else 2
    return int(importlib.import_module(BENCHES[argv[0]]).main(argv[1:]) or 0)
