"""The central mapper: every robot's odometry and observation sets, in stamp order, into ONE filter.

A set carries its robot's sightings of other robots (:class:`~mrslam_core.types.RobotSighting`),
scored in the weights of the filter that maps both robots. This is what the central SLAM node
does between its subscriptions and its publishers, without ROS, so that a live graph, a bag
replayed in real time and a bag fed offline make the same filter steps in the same order (and,
with the same seed, the same estimates); ``mrslam team``, ``mrslam dataset run`` and
``mrslam mrclam`` feed it too.

:class:`CentralMapper` (``mapper``) composes three parts, each with one job and its own
checkpoint state:

- ``ordering`` (:class:`~.ordering.Ordering`): the queue of observation sets released in stamp
  order (``max_wait``), one by one or a ``team_step`` window at a time (one filter step each),
  the odometry buffers, each set's odometry by interpolation, odometry holes and the drops of
  unusable input;
- ``lifecycle`` (:class:`~.lifecycle.Lifecycle`): robots with known and unknown starts, the
  local filters of those not merged yet, merges by map alignment, odometry resets;
- ``corrections`` (:class:`~.corrections.Corrections`): the gap re-localisation, the gap
  sampling and the map check, which redraw a robot's particles.

``config`` holds :class:`CentralConfig` and :class:`MapCheckConfig`.
"""

from mrslam_core.pipelines.central.config import ODOM_RESET_FLOOR, CentralConfig, MapCheckConfig
from mrslam_core.pipelines.central.mapper import CentralMapper, Processed

__all__ = ["ODOM_RESET_FLOOR", "CentralConfig", "CentralMapper", "MapCheckConfig", "Processed"]
