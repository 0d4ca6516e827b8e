"""Map alignment and fusion for robots with unknown start poses (004, issue 8).

A robot that does not know where it started in the common map runs its own filter (K = 1) from its
own origin. When its landmark map overlaps the central map, the two are aligned in 2D
(:mod:`.alignment`: descriptor matches, RANSAC, least-squares refinement), more than two maps are
made globally consistent (:mod:`.multimap`), matched landmarks are fused with the stationary Kalman
step (:mod:`.kalman`), and the robot is brought into the central filter particle by particle
(:mod:`.join`). A robot can also be brought in from a mutual sighting with a robot already in the
central filter (:mod:`.rendezvous`), and while the central map is still empty the known robots are
held at their posterior mean so that the common frame is not a random draw of their motion noise
(:mod:`.gauge`). Pure numpy/scipy: no rclpy.

Frame convention everywhere in this package: an alignment ``(tx [m], ty [m], θ [rad])`` maps a
point of the SOURCE map into the TARGET map, ``p_target = R(θ)·p_source + t`` (z unchanged). It is
the pose of the source map's origin in the target map's frame, so :mod:`mrslam_core.geometry.se2`
composes and inverts it.
"""
