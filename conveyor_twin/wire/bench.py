"""Measure the CDR encoders: ``python -m conveyor_twin.wire.bench`` prints medians [us/message]."""

import time
from typing import Callable, Dict

import numpy as np

from . import cdr

_REPEATS = 7
_CALLS = 2000


def _median_us(fn: Callable[[int], bytes]) -> float:
    for step in range(200):
        fn(step)
    samples = []
    for _ in range(_REPEATS):
        start = time.perf_counter()
        for step in range(_CALLS):
            fn(step)
        samples.append((time.perf_counter() - start) / _CALLS * 1e6)
    return sorted(samples)[_REPEATS // 2]


def run(parts: int = 1000) -> Dict[str, float]:
    """Return the median encode cost [us] of each hot message.

    :param parts: number of parts in PartStates.
    """
    rng = np.random.default_rng(0)
    ids = np.arange(1, parts + 1, dtype=np.uint32)
    types = np.zeros(parts, dtype=np.uint16)
    arrays = [rng.random(parts) for _ in range(6)]
    enc = cdr.PartStatesEncoder('cell')
    grid = rng.random((100, 400))
    names = [f'lb_{i}' for i in range(8)]
    blocked = np.zeros(8, dtype=bool)
    counts = np.zeros(8, dtype=np.uint32)
    dt = 1_000_000
    return {
        f'PartStates {parts} parts (encoder)':
            _median_us(lambda s: enc.encode(s * dt, s, ids, types, *arrays)),
        f'PartStates {parts} parts (encode_part_states)':
            _median_us(lambda s: cdr.encode_part_states(s * dt, 'cell', s, ids, types, *arrays)),
        'DensityGrid 400x100 from float64':
            _median_us(lambda s: cdr.encode_density_grid(s * dt, 'cell', s, 'z', 0.0, 0.0, 0.01,
                                                         400, 100, grid, 1.0)),
        'LightBarrierStates 8 barriers':
            _median_us(lambda s: cdr.encode_light_barrier_states(s * dt, 'cell', s, names,
                                                                 blocked, counts)),
        'BeltStates 3 belts':
            _median_us(lambda s: cdr.encode_belt_states(s * dt, 'cell', ('a', 'b', 'c'),
                                                        (1.0, 1.0, 1.0), (0.5, 0.5, 0.5))),
        'Clock': _median_us(lambda s: cdr.encode_clock(s * dt)),
    }


def main() -> None:
    """Print the medians."""
    for name, value in run().items():
        print(f'{name:50s} {value:8.2f} us')


if __name__ == '__main__':
    main()
