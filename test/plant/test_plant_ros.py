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


class KilledCell:
    """The chain's three cells in processes of their own (``--cell``), a monitor, and every
    ``TransferAccepted`` of one link as (entry run, exit run, seq)."""

    END = '20.0'  # s simulated; the run killed has no end: it cannot finish before the kill

    def __init__(self, context, processes, link: str) -> None:
        from conveyor_twin import contract
        from conveyor_twin.ros.plant_messages import TransferAccepted
        from conveyor_twin.ros.plant_monitor import PlantMonitor
        from conveyor_twin.ros.qos import to_rclpy
        self.plant = load_plant(CHAIN)
        self.processes = processes
        self.link_name = link
        self.monitor = PlantMonitor(self.plant, context=context)
        self.executor = make_executor(context)
        self.executor.add_node(self.monitor.node)
        self.accepted = []
        self.monitor.node.create_subscription(
            TransferAccepted, contract.link_topic(contract.TRANSFER_ACCEPTED,
                                                  self.plant.namespace, link),
            lambda m: self.accepted.extend((m.run, m.exit_run, int(s)) for s in m.seq),
            to_rclpy(contract.PLANT_QOS))

    def start(self, cell: str, run: int, mode: str = 'fast', *,
              killed: bool = False) -> subprocess.Popen:
        return self.processes.start(cli(str(CHAIN), '--cell', cell, '--no-streams', '--hold',
                                        '--mode', mode, '--duration',
                                        '0' if killed else self.END, '--run-id', str(run)),
                                    stdout=subprocess.DEVNULL)

    def link(self):
        return self.monitor.ledger().links.get(self.link_name)

    def wait(self, condition) -> None:
        assert wait_for(condition, TIMEOUT, self.executor), self.monitor.ledger().text()

    def kill(self, proc: subprocess.Popen) -> None:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()

    def finish(self) -> None:
        """Wait until every cell is done and the last reports came."""
        self.wait(self.monitor.all_done)
        wait_for(lambda: False, 0.5, self.executor)

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=2.0)
        self.monitor.destroy()


def test_a_killed_cell_leaves_its_parts_in_the_link_and_a_restart_gets_them(
        ros_context, ros_processes):
    plant = KilledCell(ros_context, ros_processes, 'first_second')
    monitor = plant.monitor
    try:
        plant.start('feeder', 1)
        plant.start('first', 1)
        second = plant.start('second', 1, 'realtime', killed=True)
        # the monitor has heard the entry cell's run 1 after it inserted parts: the ledger
        # can count what dies with it
        plant.wait(lambda: plant.link() is not None and 'second' in monitor.reports
                   and monitor.reports['second'].entry_inserted[0] >= 3)
        plant.kill(second)
        # the upstream cell runs on to its last step; what it sent and the killed cell never
        # took stays in the link, and the cell does not report done: its entry cell never
        # sent its final insertions
        end = round(float(plant.END) / plant.plant.step)
        plant.wait(lambda: monitor.reports['first'].step == end)
        wait_for(lambda: False, 0.5, plant.executor)   # a few more of its reports
        held = plant.link()
        assert held.held >= 5 and held.sent - held.inserted == held.held
        assert monitor.reports['first'].step == end and not monitor.reports['first'].done
        # the monitor tells the killed cell from the one that waits for it: its node left
        # the graph before its done report came
        plant.wait(lambda: monitor.gone_unfinished() == ['second'])
        # realtime: the new run inserts the held parts over seconds, not before this test's
        # subscriber has discovered its publisher
        plant.start('second', 2, 'realtime')
        plant.wait(lambda: monitor.gone_unfinished() == [])
        plant.finish()
    finally:
        plant.close()
    ledger = monitor.ledger()
    final = ledger.links['first_second']
    assert final.resent >= 1, ledger.text()
    assert ledger.residual == 0.0, ledger.text()
    assert [m.run for m in monitor.ended] == [1] and monitor.reports['second'].run == 2
    # no part of the link was reported inserted twice, by one run or the other (reports that
    # came before this subscriber discovered a run's publisher are not seen), and the last
    # part reported is the last the exit counts as inserted
    seqs = sorted(s for _, _, s in plant.accepted)
    assert len(seqs) == len(set(seqs)), plant.accepted
    assert seqs[-1] + 1 == final.inserted == final.sent - final.held
    assert 2 in {run for run, _, _ in plant.accepted}


def test_a_killed_feeding_cell_restarts_and_the_next_cell_takes_its_new_parts(
        ros_context, ros_processes):
    plant = KilledCell(ros_context, ros_processes, 'first_second')
    monitor = plant.monitor
    try:
        plant.start('feeder', 1)
        first = plant.start('first', 1, 'realtime', killed=True)
        plant.start('second', 1)
        # the monitor has heard the middle cell's run 1 after the last cell inserted parts
        # of it: the ledger can count what dies with it
        # (and this test's own subscriber heard some of them: its discovery of the last
        # cell's publisher may come after the monitor's)
        plant.wait(lambda: 'first' in monitor.reports and 'second' in monitor.reports
                   and monitor.reports['second'].entry_inserted[0] >= 3
                   and any(exit_run == 1 for _, exit_run, _ in plant.accepted))
        plant.kill(first)
        plant.start('first', 2)
        plant.finish()
    finally:
        plant.close()
    ledger = monitor.ledger()
    assert [m.run for m in monitor.ended] == [1] and monitor.reports['first'].run == 2
    assert ledger.residual == 0.0, ledger.text()
    assert ledger.lost > 0, ledger.text()       # run 1 had parts on its belt
    last = monitor.reports['second']
    # the last cell inserted parts of both runs of the middle cell, each part once
    assert 0 < last.entry_earlier[0] < last.entry_inserted[0], last
    by_run = {}
    for entry_run, exit_run, seq in plant.accepted:
        assert entry_run == 1
        by_run.setdefault(exit_run, []).append(seq)
    assert set(by_run) == {1, 2}, plant.accepted
    for seqs in by_run.values():
        assert seqs == sorted(set(seqs)), plant.accepted
    # run 2's parts are numbered from 0 and every one the exit counts inserted was reported
    final = ledger.links['first_second']
    assert by_run[2][-1] + 1 == final.inserted == final.sent - final.held


def test_a_bad_plant_file_exits_2_before_anything_starts(tmp_path):
    bad = tmp_path / 'plant.yaml'
    bad.write_text(CHAIN.read_text().replace('delay_steps: 40', 'delay_steps: 0'))
    for name in ('feeder.yaml', 'relay.yaml'):
        (tmp_path / name).write_text((RES / name).read_text())
    proc = subprocess.run(cli(str(bad)), capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert 'links[0].delay_steps: got 0; expected an integer in [1,' in proc.stderr
    assert proc.stdout == ''



@pytest.mark.parametrize('args, message', [
    (['--duration', '-1'], '--duration: got -1.0; expected a number of seconds >= 0'),
    (['--cell', 'first', '--run-id', '-3'], '--run-id: got -3; expected an integer in [0,'),
    (['--cell', 'third'], "no cell 'third' (cells: feeder, first, second)")])
def test_bad_options_exit_2_before_anything_starts(args, message):
    proc = subprocess.run(cli(str(CHAIN), *args), capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and message in proc.stderr and proc.stdout == ''


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


def test_the_monitor_ignores_a_late_report_of_an_ended_run(ros_context):
    from conveyor_twin.ros.plant_messages import CellProgress
    from conveyor_twin.ros.plant_monitor import PlantMonitor
    monitor = PlantMonitor(load_plant(CHAIN), context=ros_context)
    try:
        for run, step in ((1, 10), (2, 5), (1, 11)):   # run 1's last report comes late
            monitor._on_progress(CellProgress(cell='first', run=run, step=step))
        assert [(m.run, m.step) for m in monitor.ended] == [(1, 10)]
        assert (monitor.reports['first'].run, monitor.reports['first'].step) == (2, 5)
    finally:
        monitor.destroy()
