"""Killed and restarted cells on links with a capacity, over ROS 2: a run of fixed duration
finishes whichever cell was killed (upstream, middle, downstream) and the ledger balances.

The killed run has no end (``--duration 0``): it cannot finish before it is killed, however
loaded the machine is."""

from pathlib import Path
import os
import signal
import subprocess
import sys

import pytest
import yaml

from conveyor_twin.plant.loader import load_plant
from conveyor_twin.ros.compat import make_executor
from conveyor_twin.testing.ros_env import wait_for

RES = Path(__file__).resolve().parents[1] / 'resources' / 'plant'
END = '3.0'             # s simulated, of every run but the killed one
TIMEOUT = 240.0         # s, a bound for a loaded machine, not a speed requirement

pytestmark = pytest.mark.ros


def capped_chain(folder: Path) -> Path:
    """Write the test chain with a capacity on both links into ``folder``; return its path."""
    data = yaml.safe_load((RES / 'chain.yaml').read_text())
    for link in data['links']:
        link['capacity'] = 3
    for name in ('feeder.yaml', 'relay.yaml'):
        (folder / name).write_text((RES / name).read_text())
    path = folder / 'chain.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


#: The cell whose inserted parts show that the killed run has delivered (or received) parts.
WITNESS = {'feeder': ('first', 0), 'first': ('second', 0), 'second': ('second', 0)}


@pytest.mark.parametrize('killed', ['feeder', 'first', 'second'])
def test_a_killed_cell_on_capacity_links_restarts_and_the_run_finishes(
        ros_context, ros_processes, tmp_path, killed):
    from conveyor_twin.ros.plant_monitor import PlantMonitor
    path = capped_chain(tmp_path)
    plant = load_plant(path)
    monitor = PlantMonitor(plant, context=ros_context)
    executor = make_executor(ros_context)
    executor.add_node(monitor.node)

    def start(cell: str, run: int, duration: str) -> subprocess.Popen:
        return ros_processes.start(
            [sys.executable, '-m', 'conveyor_twin.cli', 'plant', str(path), '--cell', cell,
             '--no-streams', '--hold', '--mode', 'fast', '--duration', duration, '--run-id',
             str(run)], stdout=subprocess.DEVNULL)

    def wait(condition) -> None:
        assert wait_for(condition, TIMEOUT, executor), monitor.ledger().text()

    try:
        procs = {c.name: start(c.name, 1, '0' if c.name == killed else END)
                 for c in plant.cells}
        witness, k = WITNESS[killed]
        wait(lambda: killed in monitor.reports and witness in monitor.reports
             and monitor.reports[witness].entry_inserted[k] >= 3)
        os.killpg(procs[killed].pid, signal.SIGKILL)
        procs[killed].wait()
        start(killed, 2, END)
        wait(monitor.all_done)                  # deadlocked before for feeder and first
        wait_for(lambda: False, 0.5, executor)  # the last reports
    finally:
        executor.shutdown(timeout_sec=2.0)
        monitor.destroy()
    end = round(float(END) / plant.step)
    assert monitor.steps() == {'feeder': end, 'first': end, 'second': end}
    assert [(m.cell, m.run) for m in monitor.ended] == [(killed, 1)]
    assert monitor.reports[killed].run == 2
    ledger = monitor.ledger()
    assert ledger.residual == 0.0, ledger.text()
    # a capacity holds: no link ever holds more than it
    assert all(k.held <= 3 for k in ledger.links.values()), ledger.text()
