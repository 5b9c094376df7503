"""The split layout: the coordinator, micro and macro processes of one twin (no ROS imports).

The protocol between them (:mod:`~conveyor_twin.split.protocol`, over the hidden topics of
:mod:`~conveyor_twin.split.topics`), the scale processes as the coordinator's one stage
(:mod:`~conveyor_twin.split.remote`), a scale process's end (:mod:`~conveyor_twin.split.scale`),
the roles (:mod:`~conveyor_twin.split.roles`), the hand-over across processes
(:mod:`~conveyor_twin.split.mirror`) and the one launcher (:mod:`~conveyor_twin.split.launch`).
The ROS nodes (``conveyor_twin.ros``) only move the bytes.
"""
