"""Command validation: invalid commands are rejected with a reason and never queued."""

import math
import time

import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.actuation import Actuation
from conveyor_twin.coord.clock import stamp, step_ns
from conveyor_twin.coord.commands import CommandBook, CommandKind, CommandRejected


@pytest.fixture
def book() -> CommandBook:
    return CommandBook(load_cell())


@pytest.mark.parametrize('belt, speed, reason, words', [
    ('nope', 0.1, 'unknown_belt', ["'nope'", 'main']),
    ('main', math.nan, 'not_finite', ['nan']),
    ('main', math.inf, 'not_finite', ['inf']),
    ('main', 2.5, 'out_of_range', ['2.5', '[-2, 2]']),
    ('main', -2.01, 'out_of_range', ['-2.01']),
])
def test_invalid_belt_commands_are_rejected(book: CommandBook, belt: str, speed: float,
                                            reason: str, words: list) -> None:
    with pytest.raises(CommandRejected) as info:
        book.submit_belt(belt, speed)
    assert all(word in str(info.value) for word in words)
    assert book.rejected[reason] == 1 and book.rejected_total == 1
    assert book.drain(1) == []


@pytest.mark.parametrize('actuator, position, reason', [
    ('gripper', 0.1, 'unknown_actuator'),
    ('pusher', math.nan, 'not_finite'),
    ('pusher', 0.51, 'out_of_range'),
    ('pusher', -0.01, 'out_of_range'),
    ('stopper', 0.009, 'out_of_range'),
])
def test_invalid_actuator_commands_are_rejected(book: CommandBook, actuator: str,
                                                position: float, reason: str) -> None:
    with pytest.raises(CommandRejected):
        book.submit_actuator(actuator, position)
    assert book.rejected == {reason: 1}
    assert book.drain(1) == []


def test_valid_commands_are_stamped_at_the_boundary_in_order(book: CommandBook) -> None:
    book.submit_belt('main', 1.0)
    book.submit_actuator('pusher', 0.5)
    book.submit_belt('main', -2.0)
    drained = book.drain(7)
    assert [(c.kind, c.name, c.value, c.step) for c in drained] == [
        ('belt', 'main', 1.0, 7), ('actuator', 'pusher', 0.5, 7), ('belt', 'main', -2.0, 7)]
    assert book.drain(8) == []


def test_command_kinds_are_members_equal_to_their_strings(book: CommandBook) -> None:
    belt, actuator = book.validate_belt('main', 1.0), book.validate_actuator('pusher', 0.5)
    assert belt.kind is CommandKind.BELT and actuator.kind is CommandKind.ACTUATOR
    assert [f'{belt.kind}', str(actuator.kind)] == ['belt', 'actuator']
    assert {'belt': 1, 'actuator': 2}[actuator.kind] == 2   # hashes as its string
    assert CommandKind('actuator') is CommandKind.ACTUATOR


def test_scheduled_commands_come_first_at_their_step(book: CommandBook) -> None:
    book.schedule(3, book.validate_belt('main', 0.2))
    book.submit_belt('main', 0.3)
    assert [c.value for c in book.drain(2)] == [0.3]
    assert [(c.value, c.step) for c in book.drain(3)] == [(0.2, 3)]


def test_sender_and_sequence_are_kept_through_queue_schedule_and_drain(book: CommandBook) -> None:
    book.schedule(3, book.validate_actuator('pusher', 0.1, 'plan', 2))
    book.submit_belt('main', 0.3, 'ctrl', 7)
    book.submit_actuator('pusher', 0.2)                   # a command that did not say
    drained = book.drain(3)
    assert [(c.kind, c.value, c.step, c.sender, c.sequence) for c in drained] == [
        ('actuator', 0.1, 3, 'plan', 2), ('belt', 0.3, 3, 'ctrl', 7),
        ('actuator', 0.2, 3, '', 0)]


@pytest.mark.parametrize('sender, sequence, words', [
    (b'ctrl', 1, ["b'ctrl'", 'not a string']),
    ('ctrl', -1, ['-1', '[0, 4294967295]']),
    ('ctrl', 2**32, ['4294967296']),
    ('ctrl', 1.0, ['1.0']),
])
def test_a_bad_sender_or_sequence_is_rejected(book: CommandBook, sender, sequence,
                                              words: list) -> None:
    with pytest.raises(CommandRejected) as info:
        book.submit_belt('main', 0.1, sender, sequence)
    assert 'belt_command' in str(info.value)
    assert all(word in str(info.value) for word in words)
    assert book.rejected == {'bad_origin': 1} and book.drain(1) == []


def test_delayed_commands_keep_their_sender_and_sequence() -> None:
    from conveyor_twin.coord.twin import Twin
    from conveyor_twin.faults.model import FaultSpec
    twin = Twin(load_cell(), seed=1)
    faults = twin.fault_actuation
    applied = []

    def filter_commands(commands, step):
        out = type(faults).filter_commands(faults, commands, step)
        applied.extend(out)
        return out

    faults.filter_commands = filter_commands
    twin.faults.inject(FaultSpec('belt_delay_commands', 'main', {'delay': 0.005}))
    twin.step(1)
    twin.commands.submit_belt('main', 0.0, 'ctrl', 7)    # drained at step 2, applied at 7
    twin.step(6)
    assert twin.actuation.belt_target[0] == 0.0
    assert [(c.value, c.step, c.sender, c.sequence) for c in applied] == [(0.0, 7, 'ctrl', 7)]


def test_belt_ramp_respects_acceleration_and_lands_exactly() -> None:
    cell = load_cell()
    act = Actuation(cell)
    assert act.belt_speed[0] == 0.5
    act.set_belt_target(0, 1.5)
    steps = 0
    while act.belt_speed[0] != 1.5:
        before = act.belt_speed[0]
        act.advance()
        steps += 1
        assert act.belt_speed[0] - before <= cell.belts[0].acceleration * 1e-3 + 1e-15
    # 1.0 m/s at 2 m/s^2 takes 0.5 s = 500 steps
    assert steps == 500


def test_actuator_moves_at_max_speed() -> None:
    cell = load_cell()
    act = Actuation(cell)
    index = cell.actuator_index('pusher')
    act.set_actuator_target(index, 0.4)
    for _ in range(250):
        act.advance()
    assert act.actuator_position[index] == pytest.approx(0.8 * 0.25)
    for _ in range(250):
        act.advance()
    assert act.actuator_position[index] == 0.4


def test_clock_is_exact_integers() -> None:
    assert step_ns(1e-3) == 1_000_000
    assert stamp(123 * 1_000_000) == (0, 123_000_000)
    assert stamp(2_500_000_000) == (2, 500_000_000)
    with pytest.raises(ValueError):
        step_ns(1.5e-10)


def test_step_stats_window_and_total() -> None:
    from conveyor_twin.coord.timing import StepStats
    stats = StepStats(window=10)
    for i in range(100):
        stats.add((i + 1) * 1e-5)  # 0.01 .. 1.0 ms
    window = stats.window()
    assert window['max_ms'] == pytest.approx(1.0) and window['mean_ms'] == pytest.approx(0.955)
    total = stats.total()
    assert total['mean_ms'] == pytest.approx(0.505)
    assert total['max_ms'] == pytest.approx(1.0)
    assert abs(total['p50_ms'] - 0.5) <= 0.011 and abs(total['p99_ms'] - 0.99) <= 0.011


def test_step_parts_keep_the_slowest_step_of_the_last_one_or_two_windows() -> None:
    from conveyor_twin.coord.timing import StepParts
    parts = StepParts(['commands', 'micro', 'outputs'], window=3)
    assert parts.slowest() is None and parts.describe() == ''
    for laps in ([1_000, 200_000, 50_000], [1_000, 900_000, 60_000], [2_000, 100_000, 70_000]):
        parts.add(laps, cpu_ns=sum(laps) - 1_000)
    # the block of three rolled over: its slowest step is still reported
    assert parts.slowest() == pytest.approx({'commands': 0.001, 'micro': 0.9, 'outputs': 0.06,
                                             'total': 0.961, 'cpu': 0.96})
    assert parts.describe() == 'micro 0.900, outputs 0.060, commands 0.001'
    laps = [3_000, 10_000, 400_000]
    parts.add(laps, cpu_ns=50_000)
    laps[2] = 0   # the caller reuses its list: the record is a copy
    assert parts.slowest()['total'] == pytest.approx(0.961)
    parts.add([1_000, 1_000, 1_000], cpu_ns=3_000)
    parts.add([1_000, 1_000, 1_000], cpu_ns=3_000)
    # two blocks later the 0.961 ms step is gone; the slowest of the last block is reported
    assert parts.describe() == 'outputs 0.400, micro 0.010, commands 0.003'
    assert parts.slowest()['cpu'] == pytest.approx(0.05)   # it waited for the CPU


def test_the_twin_times_each_part_of_its_steps() -> None:
    from conveyor_twin.coord.twin import Twin

    class Slow:
        label = 'slow'

        def advance(self, inp) -> None:
            time.sleep(0.002)

        def reset(self, cell, seed) -> None:
            pass

    class Unnamed:
        def advance(self, inp) -> None:
            pass

        def reset(self, cell, seed) -> None:
            pass

    twin = Twin(load_cell(), seed=0, stages=[Slow(), Unnamed()])
    twin.step(3)
    parts = twin.step_parts.slowest()
    assert list(parts) == ['commands', 'slow', 'Unnamed', 'outputs', 'total', 'cpu']
    assert parts['slow'] >= 2.0 and parts['total'] >= parts['slow']
    assert parts['cpu'] < parts['slow']    # a sleeping stage takes wall time, little CPU
    assert twin.step_parts.describe().startswith('slow ')


def test_deadline_pacer_counts_overruns_without_skipping() -> None:
    import time
    from conveyor_twin.coord.timing import DeadlinePacer
    pacer = DeadlinePacer(1_000_000)
    time.sleep(0.0035)  # the first step takes 3.5 periods
    pacer.wait_next()
    assert pacer.overruns == 1
    pacer.wait_next()  # deadlines 2 and 3 are already past: no sleep, each counted
    pacer.wait_next()
    assert pacer.overruns == 3
    pacer.wait_next()  # deadline 4 lies ahead: sleeps until it
    assert time.monotonic_ns() >= pacer.start_ns + 4_000_000


def test_deadline_pacer_reports_its_latest_wake_up_after_a_deadline(monkeypatch) -> None:
    import time
    from conveyor_twin.coord import timing
    pacer = timing.DeadlinePacer(1_000_000)
    pacer.wait_next()
    assert 0.0 <= pacer.take_latest_wake() < 1.0
    time.sleep(0.003)
    pacer.wait_next()  # an overrun does not sleep: no wake-up to report
    assert pacer.overruns == 1 and pacer.take_latest_wake() == 0.0

    def oversleep(deadline_ns: int) -> None:  # another thread held the lock at the deadline
        while time.monotonic_ns() < deadline_ns + 2_000_000:
            pass
    monkeypatch.setattr(timing, 'sleep_holding_gil', oversleep)
    pacer.restart()
    pacer.wait_next()
    assert pacer.take_latest_wake() >= 2.0
    assert pacer.take_latest_wake() == 0.0  # taken: the next window starts anew
