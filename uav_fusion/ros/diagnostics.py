"""``diagnostic_msgs/DiagnosticStatus`` entries as the fusion and evaluator nodes publish them
(the evaluator's scores: :func:`evaluation_statuses`, :func:`tracks_status`), and the per-input
rate and stamp-delay checks (:class:`InputMonitor`)."""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Iterable
from typing import TYPE_CHECKING

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

if TYPE_CHECKING:
    from uav_fusion.core.scoring.evaluation import Evaluation
    from uav_fusion.core.scoring.outcomes import MultiScore

HARDWARE_ID = "uav_fusion"


def make_status(
    name: str, message: str, values: Iterable[tuple[str, str]], *, warn: bool = False
) -> DiagnosticStatus:
    """One status, level WARN when ``warn`` else OK, holding ``values`` as KeyValue pairs."""
    st = DiagnosticStatus()
    st.name = name
    st.hardware_id = HARDWARE_ID
    st.level = DiagnosticStatus.WARN if warn else DiagnosticStatus.OK
    st.message = message
    st.values = [KeyValue(key=k, value=v) for k, v in values]
    return st


class InputMonitor:
    """Rate and stamp-delay checks of one input, after diagnostic_updater's ``FrequencyStatus``
    and ``TimeStampStatus``.

    Frequency: the events of the last ``window`` diagnostics updates over their wall-clock
    span; OK ``Desired frequency met``, WARN ``Frequency too low.`` / ``Frequency too high.``
    outside [``min_hz`` (1 - ``tolerance``), ``max_hz`` (1 + ``tolerance``)], and
    ``No events recorded.`` (ERROR when ``min_hz`` > 0, else OK) without events.
    Stamp delay: receive time (the node clock: ``/clock`` with ``use_sim_time``) minus the
    header stamp, since the last update; ERROR ``Timestamps too far in future seen.`` below
    ``min_delay_s``, ``Timestamps too far in past seen.`` above ``max_delay_s``, ``Zero
    timestamp seen.`` for a zero stamp; WARN ``No data since last update.``. The worse of
    the two is the status level.
    """

    def __init__(
        self,
        name: str,
        *,
        min_hz: float = 0.0,
        max_hz: float = math.inf,
        tolerance: float = 0.1,
        window: int = 5,
        min_delay_s: float = -1.0,
        max_delay_s: float = 5.0,
    ) -> None:
        self.name = name
        self.min_hz, self.max_hz, self.tolerance = min_hz, max_hz, tolerance
        self.min_delay_s, self.max_delay_s = min_delay_s, max_delay_s
        self.count = 0
        self._history: deque[tuple[float, int]] = deque(maxlen=window + 1)
        self._history.append((time.monotonic(), 0))
        self._reset_delays()
        self.late_updates = self.early_updates = self.zero_updates = 0

    def _reset_delays(self) -> None:
        self.n_stamped = 0
        self.min_delay = math.inf
        self.max_delay = -math.inf
        self.zero_seen = False

    def tick(self, delay_s: float | None) -> None:
        """One message; ``delay_s`` None for a zero stamp."""
        self.count += 1
        self.n_stamped += 1
        if delay_s is None:
            self.zero_seen = True
            return
        if delay_s < self.min_delay:
            self.min_delay = delay_s
        if delay_s > self.max_delay:
            self.max_delay = delay_s

    def status(self, prefix: str) -> DiagnosticStatus:
        """The status for this update (and start the next window)."""
        now = time.monotonic()
        self._history.append((now, self.count))
        t0, c0 = self._history[0]
        events = self.count - c0
        span = now - t0
        freq = events / span if span > 0 else 0.0
        level = DiagnosticStatus.OK
        if events == 0:
            f_msg = "No events recorded."
            if self.min_hz > 0:
                level = DiagnosticStatus.ERROR
        elif freq < self.min_hz * (1.0 - self.tolerance):
            f_msg, level = "Frequency too low.", DiagnosticStatus.WARN
        elif freq > self.max_hz * (1.0 + self.tolerance):
            f_msg, level = "Frequency too high.", DiagnosticStatus.WARN
        else:
            f_msg = "Desired frequency met"
        t_msgs: list[str] = []
        t_level = DiagnosticStatus.OK
        if self.n_stamped == 0:
            t_msgs.append("No data since last update.")
            t_level = DiagnosticStatus.WARN
        else:
            if self.min_delay < self.min_delay_s:
                t_msgs.append("Timestamps too far in future seen.")
                self.early_updates += 1
                t_level = DiagnosticStatus.ERROR
            if self.max_delay > self.max_delay_s:
                t_msgs.append("Timestamps too far in past seen.")
                self.late_updates += 1
                t_level = DiagnosticStatus.ERROR
            if self.zero_seen:
                t_msgs.append("Zero timestamp seen.")
                self.zero_updates += 1
                t_level = DiagnosticStatus.ERROR
            if not t_msgs:
                t_msgs.append("Timestamps are reasonable.")
        values = [
            ("Events in window", str(events)),
            ("Events since startup", str(self.count)),
            ("Duration of window (s)", f"{span:.6g}"),
            ("Actual frequency (Hz)", f"{freq:.6g}"),
            ("Minimum acceptable frequency (Hz)", f"{self.min_hz * (1 - self.tolerance):.6g}"),
            ("Maximum acceptable frequency (Hz)", f"{self.max_hz * (1 + self.tolerance):.6g}"),
            ("Earliest timestamp delay", _fmt(self.min_delay)),
            ("Latest timestamp delay", _fmt(self.max_delay)),
            ("Earliest acceptable timestamp delay", f"{self.min_delay_s:.6g}"),
            ("Latest acceptable timestamp delay", f"{self.max_delay_s:.6g}"),
            ("Late diagnostic update count", str(self.late_updates)),
            ("Early diagnostic update count", str(self.early_updates)),
            ("Zero seen diagnostic update count", str(self.zero_updates)),
        ]
        self._reset_delays()
        st = make_status(f"{prefix}: {self.name} input", f"{f_msg}; {' '.join(t_msgs)}",
                         values)
        st.level = max(level, t_level)
        return st


def _fmt(v: float) -> str:
    return f"{v:.6g}" if math.isfinite(v) else "n/a"


def _num(v: float) -> str:
    return "-" if not math.isfinite(v) else f"{v:.1f}"


def evaluation_statuses(name: str, ev: Evaluation) -> list[DiagnosticStatus]:
    """The evaluator node's Table II: one status per row, named ``<name>: <row label>``."""
    return [
        make_status(
            f"{name}: {r.spec.label}",
            f"n={r.stats.count} mean={_num(r.stats.mean)} m "
            f"coverage={_num(r.stats.coverage_pct)} %",
            ((str(k), str(v)) for k, v in r.as_dict().items()
             if k not in ("key", "label", "group")),
        )
        for r in ev.rows
    ]  # fmt: skip


def tracks_status(name: str, ms: MultiScore) -> DiagnosticStatus:
    """The evaluator node's multi-target score of the tracks received so far."""
    return make_status(
        f"{name}: tracks",
        f"GOSPA mean {_num(ms.gospa_mean_m)} m, coverage {_num(ms.coverage_pct)} %",
        [("vehicles", ", ".join(u.name for u in ms.uavs)),
         ("epochs", str(ms.epochs)), ("GOSPA mean m", _num(ms.gospa_mean_m)),
         ("coverage %", _num(ms.coverage_pct)), ("id switches", str(ms.id_switches)),
         ("id switches, kept correspondence", str(ms.id_switches_kept)),
         ("false-track s", _num(ms.false_track_s)),
         ("tracks on grounded UAVs s", _num(ms.excused_track_s))]
        + [(f"{u.name} coverage %", _num(u.coverage_pct)) for u in ms.uavs],
    )  # fmt: skip
