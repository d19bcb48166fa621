"""The QoS profiles every node uses (one place, so publishers and subscribers always match).

- :func:`stream_qos`: the data streams (replays, fusion inputs and outputs, the evaluator's
  inputs): reliable, keep last ``depth``, volatile. Every message counts in the evaluation.
- :data:`CLOCK_QOS`: ``/clock``: reliable, keep last 10.
- :data:`DIAGNOSTICS_QOS`: ``/diagnostics`` and the views (path, markers, fix): keep last 10.
- :func:`make_qos`: a profile from the words a bag's metadata uses (``reliable`` /
  ``best_effort``, ``transient_local`` / ``volatile``), for the bag player and recorder.
"""

from __future__ import annotations

from typing import Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


def stream_qos(depth: int) -> QoSProfile:
    """QoS of every replay and fusion stream: reliable, keep last ``depth``, volatile."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )


CLOCK_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE
)

DIAGNOSTICS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE
)


def make_qos(
    *, reliable: bool = True, transient_local: bool = False, depth: int = 1000,
    keep_all: bool = False,
) -> QoSProfile:
    """A profile from plain choices (the bag player and recorder mirror what a bag offered)."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(
            DurabilityPolicy.TRANSIENT_LOCAL if transient_local else DurabilityPolicy.VOLATILE
        ),
    )


def qos_words(q: QoSProfile) -> dict[str, Any]:
    """A profile in the words rosbag2's metadata uses (the inverse of :func:`make_qos`)."""
    return {
        "history": "keep_all" if q.history == HistoryPolicy.KEEP_ALL else "keep_last",
        "depth": int(q.depth),
        "reliability": "best_effort" if q.reliability == ReliabilityPolicy.BEST_EFFORT
        else "reliable",
        "durability": "transient_local" if q.durability == DurabilityPolicy.TRANSIENT_LOCAL
        else "volatile",
    }
