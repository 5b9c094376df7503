"""The twin's per-step output: frames of CDR bytes built once and handed to every sink.

:mod:`~conveyor_twin.output.frame` (what a frame holds), :mod:`~conveyor_twin.output.producers`
(the frame part of each stage), :mod:`~conveyor_twin.output.hub` (the twin's output: one frame
per step to every sink), :mod:`~conveyor_twin.output.queued` (bounded queue for slow sinks),
:mod:`~conveyor_twin.output.markers` (MarkerArray CDR at viewer rate). No rclpy.
"""
