"""One line of a live stream to records, with the offline readers' own decoders.

:class:`StreamDecoder` wraps the line decoders of :mod:`uav_fusion.core.data`
(:class:`~uav_fusion.core.data.radar.RadarLines`, :class:`~uav_fusion.core.data.rf.RfLines`,
:class:`~uav_fusion.core.data.truth.TruthLines`) with a :class:`StreamPolicy`, which counts
every line it cannot use by reason and never raises: what the file reader's lenient mode
skips, a stream drops, under the same reason names (``docs/dataset.md``): malformed lines
(``bad_json``, ``not_object``, ``no_track_data``, ``bad_track_data``, ``no_time``,
``bad_csv``, ``bad_columns``, ``bad_value``, ``bad_time``, ``bad_header``), non-finite values
(``nonfinite``, radar ``track_nonfinite``), out-of-range positions (``out_of_range``,
``track_out_of_range``), a stamp going back (``time_backwards``) or repeating
(``duplicate_time``). Radar track-level reasons drop one report, not the frame. Normal lines
that carry no record (radar status lines, truth rows without a fix) are counted apart.

The records equal the file reader's for the same lines bit for bit (same decoder, same ENU
conversion; ``test/test_ingest_decode.py``), except ``line``, which numbers the lines the
stream delivered.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable

from uav_fusion.core.data._source import LinePolicy, TimeOrder, csv_fields
from uav_fusion.core.data.radar import RadarLines, radar_frames
from uav_fusion.core.data.rf import (
    AADM_HEADER,
    RfLines,
    column_key,
    header_problem,
    rf_attempts,
)
from uav_fusion.core.data.truth import TruthLines, truth_fixes
from uav_fusion.core.records import RadarFrame, RfAttempt, TruthFix
from uav_fusion.core.site import Site

Record = RadarFrame | RfAttempt | TruthFix

#: the kinds of stream, as the site's clock offsets name them
KINDS = ("radar", "rf", "truth")


class StreamPolicy(LinePolicy):
    """Counts lines that cannot be used by reason; never raises. ``warn`` gets the first
    case of each reason (for a log line)."""

    def __init__(self, warn: Callable[[str], None] | None = None) -> None:
        self.dropped: Counter[str] = Counter()
        self.info: Counter[str] = Counter()
        self.first: dict[str, str] = {}
        self.optional_unreadable = 0
        self.warn = warn

    def bad(self, line: int, reason: str, what: str) -> None:
        self.drop(reason, f"line {line}: {what}")

    def drop(self, reason: str, what: str, n: int = 1) -> None:
        """Count ``n`` dropped lines under ``reason`` (transport reasons too)."""
        if n <= 0:
            return
        self.dropped[reason] += n
        if reason not in self.first:
            self.first[reason] = what
            if self.warn is not None:
                self.warn(f"dropping {reason} ({what})")

    def soft(self, line: int, what: str) -> None:
        self.optional_unreadable += 1

    def count(self, reason: str) -> None:
        self.info[reason] += 1


class StreamDecoder:
    """Decodes the lines of one live stream of ``kind`` (radar, rf, truth) into records."""

    def __init__(
        self, kind: str, site: Site, warn: Callable[[str], None] | None = None
    ) -> None:
        if kind not in KINDS:
            raise ValueError(f"stream kind {kind!r} is not one of {', '.join(KINDS)}")
        self.kind = kind
        self.site = site
        self.policy = StreamPolicy(warn)
        self.order = TimeOrder(self.policy)
        self.line = 0
        self.non_utf8 = 0
        self.headers = 0
        offset = site.clock_offset_s(kind)
        self._radar = RadarLines(self.policy, self.order, offset) if kind == "radar" else None
        self._rf = (
            RfLines(self.policy, self.order, offset, AADM_HEADER.split(","))
            if kind == "rf" else None
        )
        self._truth = TruthLines(self.policy, self.order, offset) if kind == "truth" else None

    @property
    def last_t(self) -> float:
        """The latest accepted sensor time (-inf before the first)."""
        return self.order.last_t

    def decode(self, raw: bytes) -> list[Record]:
        """The records of one line (none for a blank, status, header or dropped line)."""
        self.line += 1
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            self.non_utf8 += 1
            text = raw.decode("utf-8", errors="replace")
        if not text.strip():
            return []
        line = self.line
        if self._radar is not None:
            frame = self._radar.decode(line, text)
            return [] if frame is None else list(radar_frames(self.site, [frame]))
        if self._rf is not None:
            if self._header(line, text):
                return []
            row = self._rf.decode(line, text)
            return [] if row is None else list(rf_attempts(self.site, [row]))
        assert self._truth is not None
        fix = self._truth.decode(line, text)
        return [] if fix is None else list(truth_fixes(self.site, [fix]))

    def _header(self, line: int, text: str) -> bool:
        """An RF header line (a field named Meas ID): take its columns; True if it was one."""
        assert self._rf is not None
        fields, _ = csv_fields(text)
        if fields is None or not any(column_key(f) == "meas id" for f in fields):
            return False
        problem = header_problem(fields, None)
        if problem is not None:
            self.policy.bad(line, "bad_header", f"{problem}; keeping the previous columns")
        else:
            self._rf.set_header(fields)
            self.headers += 1
        return True
