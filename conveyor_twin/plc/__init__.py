"""The PLC attachment: the twin's tags over OPC UA and Modbus TCP (no rclpy).

The core: :mod:`~conveyor_twin.plc.tags` (the tag map of a cell and its Modbus encoding),
:mod:`~conveyor_twin.plc.state` (:class:`PlcState`, a frame sink whose :meth:`refresh
<conveyor_twin.plc.state.PlcState.refresh>` gives every tag's value),
:mod:`~conveyor_twin.plc.writes` (:class:`PlcWriter`: writes as validated commands),
:mod:`~conveyor_twin.plc.lockstep` (:class:`StepHandshake`) and
:mod:`~conveyor_twin.plc.address`. The servers build on them.
"""
