"""The project's QoS profiles, in one place, and the profile a topic gets by its name.

Conventions (REP-2003 and the tf2 defaults):

- ``/tf_static``: reliable, transient-local, keep-last 100, so a late subscriber still receives
  every static transform published once at start-up.
- ``/clock``: reliable (not best-effort), keep-last 10; a player publishes it often.
- sensor streams (images, camera_info, clouds): reliable, keep-last 10. Best-effort would lose
  stereo halves silently on a loaded machine; the frontend's queue bounds the backlog instead.
- maps (``/map``): reliable, transient-local, keep-last 1, like map_server.
- what the central node needs to catch up on after a restart: the simulator's odometry
  (``ODOMETRY_HISTORY``, 10 s at 10 Hz) and the frontends' observation sets
  (``OBSERVATION_HISTORY``, 10 s at 5 Hz) are published transient-local; the central node
  subscribes transient-local only where every publisher offers it (:func:`adapted_to_publishers`),
  so a restarted node receives what was published while it was down and a robot driver's volatile
  odometry still matches.
- a robot's join (``/<robot>/start_pose``, where its start frame lies in the map): reliable,
  transient-local, keep-last 1, so an exploration node that starts later still places the robot.
- everything else: reliable, volatile, keep-last 10.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


def _profile(depth: int, durability: DurabilityPolicy = DurabilityPolicy.VOLATILE) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                      durability=durability)


DEFAULT = _profile(10)
SENSOR = _profile(10)
CLOCK = _profile(10)
TF = _profile(100)
TF_STATIC = _profile(100, DurabilityPolicy.TRANSIENT_LOCAL)
MAP = _profile(1, DurabilityPolicy.TRANSIENT_LOCAL)
ODOMETRY_HISTORY = _profile(100, DurabilityPolicy.TRANSIENT_LOCAL)
OBSERVATION_HISTORY = _profile(50, DurabilityPolicy.TRANSIENT_LOCAL)
JOIN = _profile(1, DurabilityPolicy.TRANSIENT_LOCAL)

_BY_NAME = {"/tf": TF, "/tf_static": TF_STATIC, "/clock": CLOCK, "/map": MAP}


def qos_for_topic(topic: str) -> QoSProfile:
    """The profile to publish or subscribe ``topic`` (fully qualified name) with.

    Transient-local topics (``/tf_static``, ``/map``, ``/<robot>/start_pose``) get their latched
    profile; all others the reliable volatile default. A transient-local publisher also serves volatile subscribers, so a
    recorder or player may use this for both ends.
    """
    if topic.endswith("/start_pose"):
        return JOIN
    return _BY_NAME.get(topic, DEFAULT)


def is_latched(topic: str) -> bool:
    """Whether ``topic`` is published transient-local by the project's convention."""
    return qos_for_topic(topic).durability == DurabilityPolicy.TRANSIENT_LOCAL


def adapted_to_publishers(infos, topic: str = "", depth: int = 100) -> QoSProfile:
    """A subscription profile compatible with every publisher of a topic (what a recorder needs).

    Args:
        infos: the ``TopicEndpointInfo`` list of ``Node.get_publishers_info_by_topic``.
        topic: the topic's name, for the default when there is no publisher yet.
        depth: keep-last depth of the subscription.

    Returns:
        Transient-local when every publisher is transient-local (so latched messages published
        before the subscription still arrive), else volatile; best-effort when any publisher is
        best-effort (a reliable subscription would not match it), else reliable; keep-last ``depth``.
    """
    if not infos:
        base = qos_for_topic(topic)
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=base.reliability,
                          durability=base.durability)
    profiles = [i.qos_profile for i in infos]
    latched = all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in profiles)
    best_effort = any(p.reliability == ReliabilityPolicy.BEST_EFFORT for p in profiles)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def to_bag_qos(profile: QoSProfile):
    """rclpy profile -> the rosbags ``Qos`` record written to a bag's metadata (offered QoS)."""
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    zero = QosTime(0, 0)
    return Qos(QosHistory(int(profile.history)), int(profile.depth), QosReliability(int(profile.reliability)),
               QosDurability(int(profile.durability)), zero, zero, QosLiveliness.AUTOMATIC, zero, False)


def from_bag_qos(offered, topic: str) -> QoSProfile:
    """The profile a player publishes ``topic`` with, from the offered QoS recorded in the bag.

    Args:
        offered: the rosbags ``Qos`` records of the topic's connection (may be empty, e.g. for bags
            written without QoS metadata).
        topic: the topic's name; without metadata the project's convention decides
            (:func:`qos_for_topic`).
    """
    from rosbags.interfaces import QosDurability, QosReliability

    base = qos_for_topic(topic)
    if not offered:
        return base
    latched = any(q.durability == QosDurability.TRANSIENT_LOCAL for q in offered)
    best_effort = all(q.reliability == QosReliability.BEST_EFFORT for q in offered)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(base.depth, 10),
                      reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)
