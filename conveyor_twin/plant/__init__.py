"""A plant of cells coupled by transfer links (no ROS imports).

:mod:`~conveyor_twin.plant.model` and :mod:`~conveyor_twin.plant.loader` describe a plant,
:mod:`~conveyor_twin.plant.geometry` the exits and entries of its links,
:mod:`~conveyor_twin.plant.link` a link's two ends, :mod:`~conveyor_twin.plant.sync` the
conservative synchronisation rule, :mod:`~conveyor_twin.plant.cell` one cell of the plant,
:mod:`~conveyor_twin.plant.ledger` the plant-wide part ledger,
:mod:`~conveyor_twin.plant.runner` all cells stepped in one process,
:mod:`~conveyor_twin.plant.stepping` a cell or the whole plant as the stepping loop
(:class:`~conveyor_twin.coord.runner.Runner`) steps it,
:mod:`~conveyor_twin.plant.supervisor` one process per cell, watched and restarted on request.
"""
