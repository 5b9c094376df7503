"""What the Foxglove view takes from the step: decimated frames, every edge, a bounded queue.

No server and no client here: the view's step side alone (``foxglove-sdk`` is not needed).
"""

from conveyor_twin import contract
from conveyor_twin.cell import load_cell
from conveyor_twin.output.frame import Frame
from conveyor_twin.viz.foxglove_view import FoxgloveView


def _view(**kwargs) -> FoxgloveView:
    streams = {('/' + t.name).replace('//', '/'): t.type_name for t in contract.STREAMS}
    view = FoxgloveView(load_cell(), streams=streams, step_s=1e-3,
                        on_command=lambda kind, name, value: None, **kwargs)
    view.active = True  # as if a client subscribed
    return view


def _frame(step: int, *, edge: bool = False, diagnostics: bool = False,
           faults: bool = False) -> Frame:
    frame = Frame()
    frame.step = step
    frame.time_ns = step * 1_000_000
    frame.clock = b'clock%d' % step
    frame.parts = b'parts%d' % step
    frame.edges = ((frame.time_ns - 500_000, b'edge%d' % step),) if edge else ()
    frame.diagnostics = b'diag%d' % step if diagnostics else None
    frame.faults = b'faults%d' % step if faults else None
    return frame


def test_one_frame_in_every_is_forwarded_whole_and_every_edge_diagnostics_and_fault_state():
    view = _view(stream_rate=50.0)  # 1 kHz steps: one frame in 20
    assert view.every == 20
    for step in range(1, 41):
        view.on_frame(_frame(step, edge=step == 5, diagnostics=step == 10,
                             faults=step == 12))
    queued = [(topic, stamp) for topic, stamp, _ in view._queue]
    assert queued == [('/clock', 1_000_000), ('/parts', 1_000_000),
                      ('/light_barrier_edges', 4_500_000), ('/diagnostics', 10_000_000),
                      ('/faults', 12_000_000), ('/clock', 21_000_000), ('/parts', 21_000_000)]
    assert view._latest['parts'] == (21_000_000, b'parts21')  # what the scene draws


def test_a_full_queue_drops_the_oldest_and_counts_them():
    view = _view(stream_rate=1000.0, backlog=4)
    for step in range(1, 11):
        view.on_frame(_frame(step))
    assert view.dropped == 16
    assert [data for _, _, data in view._queue] == [b'clock9', b'parts9', b'clock10',
                                                     b'parts10']


def test_single_messages_are_thinned_per_stream():
    view = _view(stream_rate=100.0)  # one in 10
    for step in range(1, 31):
        view.sink('/parts', step * 1_000_000, b'p')
        if step % 7 == 0:
            view.sink('/light_barrier_edges', step * 1_000_000, b'e')
    stamps = [(topic, stamp // 1_000_000) for topic, stamp, _ in view._queue]
    assert stamps == [('/parts', 1), ('/light_barrier_edges', 7), ('/parts', 11),
                      ('/light_barrier_edges', 14), ('/parts', 21), ('/light_barrier_edges', 21),
                      ('/light_barrier_edges', 28)]
