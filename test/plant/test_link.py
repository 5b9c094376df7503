"""A link's two ends without cells: release at the leave step plus the delay, in order; the
backlog at a blocked entry; the capacity; repeats and restarts; the synchronisation rule."""

import pytest

from conveyor_twin.plant.link import Acceptances, LinkEntry, LinkExit, Transit
from conveyor_twin.plant.model import EndFrame, Link, LinkEnd
from conveyor_twin.plant.sync import horizon, may_step, UNBOUNDED

FRAME = EndFrame(0.0, 0.0, 0.0, 0.0, 0.1, 0.1)


def link(delay: int = 5, capacity: int = 0) -> Link:
    return Link('ab', LinkEnd('a', sink='exit'), LinkEnd('b', belt='main'), delay, capacity,
                (0,), FRAME, FRAME)


def part(seq: int, step: int) -> Transit:
    return Transit(seq, step, 100 + seq, 100 + seq, 0, 0.0, 0.01 * seq, 0.0, 0.5, 0.0, 0.0)


def test_parts_enter_at_leave_step_plus_delay_in_order():
    x, e = LinkExit(link(5)), LinkEntry(link(5))
    x.add(part(0, 3))
    x.add(part(1, 4))
    x.through = 4
    e.receive(x.batch())
    placed = []
    for s in range(1, 12):
        e.insert(s, lambda p: placed.append((p.seq, s)) or 1)
    assert placed == [(0, 8), (1, 9)]
    back = e.batch()
    assert (back.seq, back.step) == ([0, 1], [8, 9])
    x.receive(back)
    assert x.in_link == 0 and x.accepted == 2 and not x.held


def test_a_blocked_entry_keeps_the_parts_waiting_in_order():
    x, e = LinkExit(link(2)), LinkEntry(link(2))
    for k in range(3):
        x.add(part(k, 1))
    e.receive(x.batch())
    assert e.insert(3, lambda p: 0) == (0, 3)          # entry occupied: all three wait
    assert e.insert(4, lambda p: 1 if p.seq == 0 else 0) == (1, 2)
    assert e.insert(5, lambda p: 1) == (2, 0)
    assert e.batch().seq == [0, 1, 2]


def test_capacity_counts_insertions_up_to_step_minus_delay():
    x = LinkExit(link(3, capacity=2))
    assert x.room(1) == 2
    x.add(part(0, 1))
    x.add(part(1, 1))
    assert x.room(2) == 0
    x.receive(Acceptances('ab', through=4, run=0, seq=[0], step=[4]))
    assert x.room(6) == 0           # inserted at 4: seen from step 7 on
    assert x.room(7) == 1
    assert x.in_link == 1


def test_repeats_are_ignored_and_a_gap_is_an_error():
    x, e = LinkExit(link()), LinkEntry(link())
    x.add(part(0, 1))
    b = x.batch()
    e.receive(b)
    e.receive(b)
    assert len(e.queue) == 1
    x.add(part(1, 2))
    x.batch()                        # lost
    x.add(part(2, 3))
    with pytest.raises(ValueError, match='part 2 arrived, 1 expected'):
        e.receive(x.batch())


def test_a_restarted_entry_gets_everything_not_inserted():
    x, e = LinkExit(link(1)), LinkEntry(link(1), run=1)
    for k in range(4):
        x.add(part(k, 1))
    e.receive(x.batch())
    e.insert(2, lambda p: 1 if p.seq < 2 else 0)
    x.receive(e.batch())
    assert x.in_link == 2
    fresh = LinkEntry(link(1), run=2)          # the entry cell restarted: empty
    x.add(part(4, 5))
    fresh.receive(x.batch())                    # starts after the held parts: ignored
    assert not fresh.queue
    x.receive(fresh.batch())                    # the exit learns of the new run
    assert x.resent == 3
    fresh.receive(x.batch())
    assert [p.seq for p in fresh.queue] == [2, 3, 4]
    fresh.insert(10, lambda p: 1)
    x.receive(fresh.batch())
    assert x.in_link == 0 and x.accepted == 5


def test_the_rule_waits_for_upstream_and_for_a_full_links_downstream():
    e = LinkEntry(link(5))
    free, bounded = LinkExit(link(4)), LinkExit(link(3, capacity=1))
    assert horizon([], [free]) == UNBOUNDED
    e.peer_through = 10
    assert may_step(15, [e], [free]) and not may_step(16, [e], [free])
    bounded.peer_through = 7
    assert horizon([e], [free, bounded]) == 10


def test_an_entry_follows_a_restarted_exit_and_drops_what_the_old_run_left():
    old, e = LinkExit(link(2), run=1), LinkEntry(link(2), run=7)
    for k in range(3):
        old.add(part(k, 1))
    old.through = 3
    e.receive(old.batch())
    e.insert(3, lambda p: 1 if p.seq == 0 else 0)
    e.through = 5
    old.receive(e.batch())
    assert old.accepted == 1
    new = LinkExit(link(2), run=2)            # the exit cell restarted: seq and steps from 0
    new.add(part(0, 1))
    new.through = 1
    new.receive(e.batch())                    # about run 1: says nothing about run 2
    assert new.peer_through == 0 and len(new.held) == 1
    e.receive(new.batch())
    assert (e.peer_run, e.offset, e.earlier, e.dropped) == (2, 5, 1, 2)
    assert [p.seq for p in e.queue] == [0] and e.peer_through == 6
    old.add(part(3, 4))
    e.receive(old.batch())                    # late batch of the ended run: ignored
    assert [p.seq for p in e.queue] == [0]
    assert e.insert(7, lambda p: 1) == (0, 0)  # left at 1 in run 2's steps: due at 5 + 1 + 2
    assert e.insert(8, lambda p: 1) == (1, 0)
    e.through = 8
    back = e.batch()
    assert (back.exit_run, back.through, back.seq, back.step) == (2, 3, [0], [3])
    new.receive(back)
    assert new.accepted == 1 and not new.held and new.peer_through == 3
    assert e.inserted == 2


def test_an_exit_is_settled_by_its_entry_runs_final_batch_only():
    x, e = LinkExit(link(2)), LinkEntry(link(2))
    x.add(part(0, 1))
    x.through = 1
    e.receive(x.batch())
    e.insert(3, lambda p: 1)
    x.receive(e.batch())
    assert not x.peer_final and x.accepted == 1
    e.finished = True
    last = e.batch()
    assert last.final
    x.receive(last)
    assert x.peer_final
    # a report about another run of this exit says nothing about this run
    x.receive(Acceptances('ab', through=9, run=0, exit_run=7, final=False))
    assert x.peer_final
    # a restarted entry cell runs again: not settled until its own final batch
    x.receive(Acceptances('ab', through=0, run=1, exit_run=0, starting=True))
    assert not x.peer_final
    x.receive(Acceptances('ab', through=5, run=1, exit_run=0, final=True))
    assert x.peer_final
