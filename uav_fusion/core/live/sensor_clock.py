"""The sensor time as a live node can know it.

A node's clock (simulated, else wall) and the sensors' stamps need not agree: the sensors may
run on their own clocks, and every input arrives after some delay. :class:`SensorClock` keeps
``stamp - node clock`` of the last ``window`` inputs fused; the largest is how far the sensor
time runs ahead of the node's clock less the quickest input's delay, so the sensor time at
node-clock time ``now`` is ``now`` plus that. The fusion node moves its fixed-rate output on to
it when the inputs stall (``stall_timeout_s``) and, with ``output_delay_s``, as time passes.
"""

from __future__ import annotations

from collections import deque

#: Inputs the estimate looks back over.
WINDOW = 64


class SensorClock:
    """The sensor time from the node's clock and the stamps of recent inputs (module text)."""

    def __init__(self, window: int = WINDOW) -> None:
        self._ahead: deque[float] = deque(maxlen=window)

    @property
    def known(self) -> bool:
        """Whether an input has been seen (before that the node's clock is all there is)."""
        return bool(self._ahead)

    def observe(self, stamp_t: float, node_t: float) -> None:
        """An input stamped ``stamp_t`` was fused at node-clock time ``node_t``."""
        self._ahead.append(stamp_t - node_t)

    def at(self, node_t: float) -> float:
        """The sensor time at node-clock time ``node_t``."""
        return node_t + max(self._ahead) if self._ahead else node_t
