"""conveyor_twin: a real-time digital twin of a conveyor cell (ROS 2)."""

__version__ = '0.1.0'

from conveyor_twin.numba_cache import drop_stale_caches, use_package_cache  # noqa: E402

drop_stale_caches()  # before any kernel module is imported
use_package_cache()
