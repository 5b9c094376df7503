"""The coupling of the micro and macro scales (no ROS imports).

- :mod:`.scale`, :class:`~.scale.ScaleCoupling`: the hand-over between the scales after both
  stepped (capture into density, sinks, release as whole parts, ``auto`` tiles, the ledger);
  :mod:`.region`: what it keeps per macro grid;
- :mod:`.handover`: its compiled kernels, one module per part of the hand-over;
- :mod:`.tiles`: the micro/macro tiles of ``auto`` zones;
- :mod:`.macro_barriers`: light barriers in ``macro`` zones, modelled on the density, and
  :mod:`.zone_barriers`: their holder for the micro stage.
"""
