"""``conveyor-twin bench testing``: a lockstep controller test against the twin's fast mode.

Both runs simulate the same span of the default cell, composed in this process:

- ``fast``: the twin in ``fast`` mode (steps as fast as it can, publishes every stream), timed
  from start until its last step;
- ``lockstep``: :class:`conveyor_twin.testing.LockstepTwin` with a stop-on-barrier controller
  node attached in the same process, stepped ``chunk`` steps per ``step`` call, each call
  waiting until every stream has reached the harness and the twin has answered every command.

The runs alternate (fast, lockstep, fast, ...) so that machine load hits both alike; the bench
prints each run, the medians and the ratio lockstep / fast. Each run takes a ROS domain of its
own on loopback.
"""

import argparse
import json
import statistics
import sys
import time
from typing import Any, Dict, List

DEFAULT_SECONDS = 10.0
DEFAULT_REPEATS = 3
DEFAULT_SEED = 1
STOP_PAUSE_NS = 500_000_000


def run_fast(seconds: float, seed: int) -> float:
    """Run the default cell in fast mode for ``seconds`` of simulation time; return wall [s]."""
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    from conveyor_twin.cell import load_cell
    from conveyor_twin.coord.timing import TimeMode
    from conveyor_twin.ros.compose import ComposedTwin
    from conveyor_twin.testing.ros_env import lease_domain_id

    cell = load_cell()
    lease = lease_domain_id()
    context = Context()
    rclpy.init(context=context, domain_id=lease.domain_id,
               signal_handler_options=SignalHandlerOptions.NO)
    try:
        twin = ComposedTwin(cell, seed=seed, mode=TimeMode.FAST, context=context,
                            markers_rate=0.0, max_steps=round(seconds / cell.settings.step))
        start = time.perf_counter()
        twin.start()
        while twin.runner.running:
            time.sleep(0.005)
        wall = time.perf_counter() - start
        twin.stop()
        return wall
    finally:
        rclpy.try_shutdown(context=context)
        lease.release()


def make_controller(context: Any) -> Any:
    """Return a node that stops belt ``main`` on a blocking edge of ``lb_infeed`` and restarts
    it 0.5 s of simulation time later (what examples/stop_on_barrier.py does)."""
    from conveyor_twin_msgs.msg import BeltCommand, LightBarrierEdge, LightBarrierStates
    from rclpy.node import Node

    from conveyor_twin import contract
    from conveyor_twin.ros.qos import COMMAND_QOS, EDGE_QOS, STREAM_QOS

    class StopOnBarrier(Node):
        def __init__(self) -> None:
            super().__init__('bench_stop_on_barrier', context=context)
            self.stopped_at_ns = None
            self.commands = self.create_publisher(BeltCommand, contract.BELT_COMMAND.name,
                                                  COMMAND_QOS)
            self.create_subscription(LightBarrierEdge, contract.LIGHT_BARRIER_EDGES.name,
                                     self.on_edge, EDGE_QOS)
            self.create_subscription(LightBarrierStates, contract.LIGHT_BARRIERS.name,
                                     self.on_states, STREAM_QOS)

        def on_edge(self, edge: LightBarrierEdge) -> None:
            if edge.name == 'lb_infeed' and edge.blocked and self.stopped_at_ns is None:
                self.stopped_at_ns = edge.header.stamp.sec * 10**9 + edge.header.stamp.nanosec
                self.commands.publish(BeltCommand(belt='main', speed=0.0))

        def on_states(self, states: LightBarrierStates) -> None:
            now = states.header.stamp.sec * 10**9 + states.header.stamp.nanosec
            if self.stopped_at_ns is not None and now - self.stopped_at_ns >= STOP_PAUSE_NS:
                self.stopped_at_ns = None
                self.commands.publish(BeltCommand(belt='main', speed=0.5))

    return StopOnBarrier()


def run_lockstep(seconds: float, seed: int, chunk: int) -> Dict[str, float]:
    """Run a controller test of ``seconds`` of simulation time; return wall [s] and counts."""
    from conveyor_twin.testing import LockstepTwin

    start = time.perf_counter()
    with LockstepTwin(seed=seed, chunk=chunk) as twin:
        ready = time.perf_counter()
        twin.add_node(make_controller(twin.context))
        twin.step_for(seconds)
        stepped = time.perf_counter()
        commands = len(twin.command_log())
    end = time.perf_counter()
    return {'wall_s': end - start, 'startup_s': ready - start, 'stepping_s': stepped - ready,
            'commands': commands}


def main(argv: List[str]) -> int:
    """Entry point of ``conveyor-twin bench testing``."""
    p = argparse.ArgumentParser(prog='conveyor-twin bench testing', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--seconds', type=float, default=DEFAULT_SECONDS,
                   help='simulated time per run [s]')
    p.add_argument('--repeats', type=int, default=DEFAULT_REPEATS, help='runs of each kind')
    p.add_argument('--seed', type=int, default=DEFAULT_SEED)
    p.add_argument('--chunk', type=int, nargs='+', default=[10],
                   help='steps per step call of the lockstep runs (several: one run each)')
    p.add_argument('--json', action='store_true', help='print one JSON object')
    args = p.parse_args(argv)
    run_fast(0.05, args.seed)  # compiled kernels loaded, DDS libraries warm
    fast: List[float] = []
    lockstep: Dict[int, List[Dict[str, float]]] = {c: [] for c in args.chunk}
    for k in range(args.repeats):
        fast.append(run_fast(args.seconds, args.seed))
        if not args.json:
            print(f'run {k + 1}: fast {fast[-1]:.2f} s', flush=True)
        for chunk in args.chunk:
            figures = run_lockstep(args.seconds, args.seed, chunk)
            lockstep[chunk].append(figures)
            if not args.json:
                print(f'run {k + 1}: lockstep chunk {chunk}: {figures["wall_s"]:.2f} s '
                      f'(start-up {figures["startup_s"]:.2f} s, stepping '
                      f'{figures["stepping_s"]:.2f} s, {figures["commands"]} commands)',
                      flush=True)
    fast_median = statistics.median(fast)
    result: Dict[str, Any] = {'simulated_s': args.seconds, 'repeats': args.repeats,
                              'fast_median_s': round(fast_median, 3), 'lockstep': {}}
    for chunk, runs in lockstep.items():
        wall = statistics.median(r['wall_s'] for r in runs)
        result['lockstep'][chunk] = {
            'median_s': round(wall, 3),
            'stepping_median_s': round(statistics.median(r['stepping_s'] for r in runs), 3),
            'ratio_to_fast': round(wall / fast_median, 2)}
    if args.json:
        print(json.dumps(result))
    else:
        print(f'{args.seconds:g} s of the default cell, median of {args.repeats}: fast mode '
              f'{fast_median:.2f} s')
        for chunk, figures in result['lockstep'].items():
            print(f'  lockstep test, controller attached, chunk {chunk}: '
                  f'{figures["median_s"]:.2f} s = {figures["ratio_to_fast"]:.2f} x fast')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
