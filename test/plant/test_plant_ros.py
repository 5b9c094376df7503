"""The plant over ROS 2: one process per cell gives the bits of all cells in one process
(fast and lockstep); a killed cell's link holds what it could not deliver, a restarted one
gets it, and the ledger balances; the CLI refuses a bad plant file before starting."""

import json
import os
from pathlib import Path
import signal
import subprocess
import sys

import pytest

from conveyor_twin.plant.loader import load_plant
from conveyor_twin.plant.runner import PlantRunner
from conveyor_twin.ros.compat import make_executor
from conveyor_twin.testing.ros_env import wait_for

RES = Path(__file__).resolve().parents[1] / 'resources' / 'plant'
CHAIN = RES / 'chain.yaml'
DURATION = 1.5          # s simulated
STEPS = 1500
TIMEOUT = 240.0         # s, a bound for a loaded machine, not a speed requirement

pytestmark = pytest.mark.ros


def cli(*args: str) -> list:
    return [sys.executable, '-m', 'conveyor_twin.cli', 'plant', *args]


def reference_hashes() -> dict:
    runner = PlantRunner(load_plant(CHAIN))
    runner.run_to(STEPS)
    return runner.state_hashes(), runner.ledger()


@pytest.mark.parametrize('mode', ['fast', 'lockstep'])
def test_one_process_per_cell_gives_the_bits_of_one_process(ros_processes, mode):
    proc = ros_processes.start(cli(str(CHAIN), '--processes', '--no-streams', '--mode', mode,
                                   '--duration', str(DURATION), '--json', '--quiet'),
                               stdout=subprocess.PIPE, text=True)
    out, _ = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 0, out
    summary = json.loads(out.strip().splitlines()[-1])
    hashes, ledger = reference_hashes()
    assert summary['layout'] == 'processes' and summary['steps'] == {
        'feeder': STEPS, 'first': STEPS, 'second': STEPS}
    assert summary['state_hashes'] == hashes
    assert summary['ledger']['residual'] == 0.0
    assert summary['ledger']['left'] == ledger.left > 0
    assert summary['ledger']['in_links'] == ledger.in_links


def test_composed_cli_gives_the_same_bits(ros_processes):
    proc = ros_processes.start(cli(str(CHAIN), '--composed', '--duration', str(DURATION),
                                   '--json', '--quiet'), stdout=subprocess.PIPE, text=True)
    out, _ = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 0, out
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary['state_hashes'] == reference_hashes()[0]


def test_a_killed_cell_leaves_its_parts_in_the_link_and_a_restart_gets_them(
        ros_context, ros_processes):
    from conveyor_twin.ros.plant_node import PlantMonitor
    plant = load_plant(CHAIN)
    monitor = PlantMonitor(plant, context=ros_context)
    executor = make_executor(ros_context)
    executor.add_node(monitor.node)
    accepted = []
    from conveyor_twin.ros.plant_node import TransferAccepted
    from conveyor_twin import contract
    from conveyor_twin.ros.qos import to_rclpy
    monitor.node.create_subscription(
        TransferAccepted, contract.link_topic(contract.TRANSFER_ACCEPTED, plant.namespace,
                                              'first_second'),
        lambda m: accepted.extend((m.run, int(s)) for s in m.seq),
        to_rclpy(contract.PLANT_QOS))
    end = '60.0'  # s simulated: long enough for the kill and the restart in any load

    def start(cell: str, run: int) -> subprocess.Popen:
        return ros_processes.start(cli(str(CHAIN), '--cell', cell, '--no-streams', '--hold',
                                       '--duration', end, '--run-id', str(run)),
                                   stdout=subprocess.DEVNULL)

    def link():
        return monitor.ledger().links.get('first_second')

    try:
        start('feeder', 1)
        start('first', 1)
        second = start('second', 1)
        # the monitor has heard the entry cell's run 1 after it inserted parts: the ledger
        # can count what dies with it
        assert wait_for(lambda: link() is not None and 'second' in monitor.reports
                        and monitor.reports['second'].entry_inserted[0] >= 3, TIMEOUT,
                        executor), monitor.ledger().text()
        os.killpg(second.pid, signal.SIGKILL)
        second.wait()
        before = link().sent
        # the upstream cell runs on; what it sends stays in the link
        assert wait_for(lambda: link().sent >= before + 5 or monitor.all_done(), TIMEOUT,
                        executor)
        held = link()
        assert held.held >= 1 and held.sent - held.inserted == held.held
        start('second', 2)
        assert wait_for(monitor.all_done, TIMEOUT, executor), monitor.ledger().text()
        wait_for(lambda: False, 0.5, executor)  # the last reports
    finally:
        executor.shutdown(timeout_sec=2.0)
        monitor.destroy()
    ledger = monitor.ledger()
    final = ledger.links['first_second']
    assert final.resent >= 1, ledger.text()
    assert ledger.residual == 0.0, ledger.text()
    assert [m.run for m in monitor.ended] == [1] and monitor.reports['second'].run == 2
    # no part of the link was reported inserted twice, by one run or the other (reports that
    # came before this subscriber discovered a run's publisher are not seen), and the last
    # part reported is the last the exit counts as inserted
    seqs = sorted(s for _, s in accepted)
    assert len(seqs) == len(set(seqs)), accepted
    assert seqs[-1] + 1 == final.inserted == final.sent - final.held
    assert 2 in {run for run, _ in accepted}


def test_a_bad_plant_file_exits_2_before_anything_starts(tmp_path):
    bad = tmp_path / 'plant.yaml'
    bad.write_text(CHAIN.read_text().replace('delay_steps: 40', 'delay_steps: 0'))
    for name in ('feeder.yaml', 'relay.yaml'):
        (tmp_path / name).write_text((RES / name).read_text())
    proc = subprocess.run(cli(str(bad)), capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert 'links[0].delay_steps: got 0; expected an integer in [1,' in proc.stderr
    assert proc.stdout == ''


def test_ledger_of_a_restarted_cell_counts_what_died_with_it():
    from conveyor_twin.ros.plant_node import CellProgress, ledger_of

    def report(cell, run, **kw):
        m = CellProgress(cell=cell, run=run)
        for k, v in kw.items():
            setattr(m, k, v)
        return m
    up = report('a', 1, entered=20.0, in_cell=10.0, exit_link=['ab'], exit_sent=[10],
                exit_accepted=[8], exit_resent=[3])
    old = report('b', 1, in_cell=3.0, left=2.0, entry_link=['ab'], entry_inserted=[5],
                 entry_waiting=[0])
    new = report('b', 2, in_cell=2.0, entry_link=['ab'], entry_inserted=[2],
                 entry_waiting=[1])
    ledger = ledger_of({'a': up, 'b': new}, [old])
    # the old run held 3 at its last report and reported 1 more inserted after it
    assert ledger.lost == 3 + (8 - 5 - 2)
    assert ledger.links['ab'].held == 2 and ledger.links['ab'].waiting == 1
    assert ledger.in_cells == 12 and ledger.left == 2 and ledger.residual == 0.0
    assert ledger_of({'a': up, 'b': new}).lost == 0.0


def test_composed_plant_records_every_cell(ros_processes, tmp_path):
    from conveyor_twin.record.reader import read_messages, read_metadata
    proc = ros_processes.start(cli(str(CHAIN), '--composed', '--duration', '0.3', '--record',
                                   str(tmp_path), '--json', '--quiet'),
                               stdout=subprocess.PIPE, text=True)
    out, _ = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 0, out
    for name in ('feeder', 'first', 'second'):
        path = str(tmp_path / f'{name}.mcap')
        meta = read_metadata(path)
        assert any(m.get('plant_cell') == name for m in meta.values()), meta
        steps = [m for m in read_messages(path, topics=[f'/{name}/parts'])]
        assert len(steps) == 300
