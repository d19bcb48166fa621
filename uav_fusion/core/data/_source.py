"""The line, time and policy machinery the dataset readers share.

A :class:`Source` holds the decoded lines of one file with the strict/lenient bookkeeping;
:class:`TimeOrder` applies the time-ordering policy; the rest parse clock readings and
numbers. The public reader API is re-exported by :mod:`uav_fusion.core.data`.
"""

from __future__ import annotations

import csv
import math
import re
from collections import Counter
from datetime import UTC, datetime
from pathlib import Path

from uav_fusion.core.errors import DataError
from uav_fusion.core.records import LoadReport

# Times outside this window are not plausible for these logs (catches seconds-since-boot
# clocks, milliseconds written as seconds, and years mistyped).
T_MIN = 946684800.0  # 2000-01-01T00:00:00Z
T_MAX = 4102444800.0  # 2100-01-01T00:00:00Z

_WALL_RE = re.compile(
    r"\d{4}-\d{2}-\d{2}[ T]\d{2}:\d{2}:\d{2}(?:\.\d{1,9})?(?:Z|[+-]\d{2}:?\d{2})?"
)
_UNIX_RE = re.compile(r"\+?\d+(?:\.\d*)?")


def fmt_utc(t: float) -> str:
    """A UTC unix time as ISO text with milliseconds (for messages)."""
    if not math.isfinite(t) or not -62135596800.0 < t < 253402300800.0:
        return repr(t)
    s = datetime.fromtimestamp(t, UTC).isoformat(timespec="milliseconds")
    return s.replace("+00:00", "Z")


def parse_clock_time(text: str) -> tuple[float, str] | None:
    """Parse a file clock reading; return (unix seconds, kind) or None if not a time.

    Accepted: ``YYYY-MM-DD HH:MM:SS[.f…]`` (``T`` also accepted as separator; a trailing
    ``Z`` or ``±HH:MM`` makes it an absolute time) and plain unix seconds. ``kind`` is
    ``"wall"`` (no zone: read as the file's own clock, to which the clock offset applies),
    ``"zoned"`` (carries its zone: already absolute, no offset applies) or ``"unix"``
    (epoch seconds of the file's clock; the offset applies). Values outside 2000–2100 are
    rejected as implausible.
    """
    s = text.strip()
    if _WALL_RE.fullmatch(s):
        try:
            dt = datetime.fromisoformat(s)
        except ValueError:
            return None
        kind = "zoned" if dt.tzinfo is not None else "wall"
        if dt.tzinfo is None:
            dt = dt.replace(tzinfo=UTC)
        t = dt.timestamp()
    elif _UNIX_RE.fullmatch(s):
        t = float(s)
        kind = "unix"
    else:
        return None
    if not T_MIN <= t <= T_MAX:
        return None
    return t, kind


def csv_fields(text: str) -> tuple[list[str], None] | tuple[None, str]:
    """The fields of one CSV line, or (None, what was wrong) if it is not a CSV row.

    The ``csv`` module refuses a carriage return or line feed inside an unquoted field
    (a file written half with Windows line ends, a transfer that mangled them) and a field
    longer than its limit (131 072 characters); both make the row unreadable instead of
    ending the read.
    """
    try:
        return next(csv.reader([text])), None
    except csv.Error as exc:
        cr = text.find("\r")
        if cr >= 0 and "new-line" in str(exc):
            return None, (
                f"carriage return (\\r) inside an unquoted field at column {cr + 1}"
            )
        return None, f"not a CSV row: {exc}"


def to_float(text: str) -> float | None:
    """A float from text, or None if it is not a number (NaN/inf are returned as such)."""
    try:
        return float(text)
    except ValueError:
        return None


def to_int(text: str) -> int | None:
    """An integer from text (``"12"`` or ``"12.0"``), or None."""
    s = text.strip()
    try:
        return int(s)
    except ValueError:
        pass
    x = to_float(s)
    if x is None or not math.isfinite(x) or x != int(x):
        return None
    return int(x)


class LinePolicy:
    """What the line decoders of the three formats report to: a row that cannot be used
    (:meth:`bad`), an optional field that cannot be read (:meth:`soft`) and a line that is
    normal content but no record (:meth:`count`: radar status lines, truth rows without a
    fix). :class:`Source` implements it for a file read in strict or lenient mode; the live
    stream decoders (:mod:`uav_fusion.core.ingest.decode`) count and never raise."""

    def bad(self, line: int, reason: str, what: str) -> None:
        raise NotImplementedError

    def soft(self, line: int, what: str) -> None:
        raise NotImplementedError

    def count(self, reason: str) -> None:
        raise NotImplementedError


class Source(LinePolicy):
    """The decoded lines of one input file plus the strict/lenient bookkeeping.

    Lines keep their 1-based numbers. A missing or unreadable file raises
    :class:`DataError` in both modes. Bytes that are not UTF-8 raise in strict mode; in
    lenient mode they are replaced by U+FFFD (so the row is only lost if the bad byte sits
    in a field that must be parsed) and a note gives their count and first line.
    """

    def __init__(self, path: str | Path, strict: bool) -> None:
        self.path = Path(path)
        self.strict = strict
        self.report = LoadReport(self.path)
        self._soft: Counter[str] = Counter()
        self._soft_first: str = ""
        self.lines, self.unterminated = self._read()

    # --- reading ---------------------------------------------------------------------
    def _read(self) -> tuple[list[tuple[int, str]], int]:
        """Non-blank (number, text) lines; and the number of an unterminated last line (0)."""
        p = self.path
        if not p.exists():
            raise DataError(p, None, "file not found")
        if not p.is_file():
            raise DataError(p, None, "not a regular file")
        try:
            data = p.read_bytes()
        except OSError as exc:
            raise DataError(p, None, f"cannot read file: {exc.strerror or exc}") from None
        raw = data.split(b"\n")
        terminated = raw[-1] == b""
        if terminated:
            raw.pop()
        try:
            texts = data.decode("utf-8").split("\n")
            if terminated:
                texts.pop()
        except UnicodeDecodeError:
            texts = []
            bad: list[int] = []
            for i, b in enumerate(raw, 1):
                try:
                    texts.append(b.decode("utf-8"))
                except UnicodeDecodeError as exc:
                    if self.strict:
                        raise DataError(
                            p, i, f"byte 0x{b[exc.start]:02x} at byte {exc.start + 1} is not UTF-8"
                        ) from None
                    bad.append(i)
                    texts.append(b.decode("utf-8", errors="replace"))
            self.report.notes.append(
                f"{len(bad)} line(s) hold bytes that are not UTF-8 (first: line {bad[0]}); "
                "they were replaced by U+FFFD"
            )
        if texts and texts[0].startswith("\ufeff"):
            texts[0] = texts[0][1:]
        lines = [(i, s.rstrip("\r")) for i, s in enumerate(texts, 1) if s.strip()]
        last = len(texts) if (texts and not terminated) else 0
        return lines, last

    # --- policy ----------------------------------------------------------------------
    def bad(self, line: int, reason: str, what: str) -> None:
        """A row that cannot be used: raise (strict) or skip and count it under ``reason``.

        A failing unterminated last line is reported as ``truncated``.
        """
        if line == self.unterminated and reason not in ("time_backwards", "duplicate_time"):
            reason = "truncated"
            what = f"truncated last line (no newline at end of file): {what}"
        if self.strict:
            raise DataError(self.path, line, what)
        self.report.skip(reason)

    def soft(self, line: int, what: str) -> None:
        """An optional field that cannot be read: raise (strict) or use None and note it."""
        if self.strict:
            raise DataError(self.path, line, what)
        if not self._soft:
            self._soft_first = f"line {line}: {what}"
        self._soft["n"] += 1

    def count(self, reason: str) -> None:
        """A line that is normal content but no record (counted in both modes)."""
        self.report.skip(reason)

    def empty(self, what: str = "empty file") -> None:
        """The file holds no data rows: raise (strict) or note it."""
        if self.strict:
            raise DataError(self.path, None, what)
        self.report.notes.append(what)

    def finish(self) -> LoadReport:
        if self._soft:
            self.report.notes.append(
                f"{self._soft['n']} optional field value(s) unreadable, read as missing "
                f"(first: {self._soft_first})"
            )
        return self.report


class TimeOrder:
    """The time-ordering policy: rows must advance in time.

    A row earlier than the last accepted row is skipped as ``time_backwards``; a row at
    exactly the same time is skipped as ``duplicate_time`` (strict mode raises for both).
    """

    def __init__(self, src: LinePolicy) -> None:
        self.src = src
        self.last_t = -math.inf
        self.last_line = 0

    def accept(self, t: float, line: int) -> bool:
        if t > self.last_t:
            self.last_t, self.last_line = t, line
            return True
        if t == self.last_t:
            self.src.bad(line, "duplicate_time", f"time {fmt_utc(t)} repeats line {self.last_line}")
        else:
            self.src.bad(
                line,
                "time_backwards",
                f"time {fmt_utc(t)} is earlier than {fmt_utc(self.last_t)} on line "
                f"{self.last_line}",
            )
        return False


def unix_clock_note(n_unix: int, source: str, offset_s: float) -> str:
    return (
        f"{n_unix} timestamp(s) are unix seconds; the {source} clock offset "
        f"({offset_s / 3600.0:+g} h) was applied to them as to wall-clock times — if the "
        f"logger wrote true UTC epoch seconds, set clock_offsets_h.{source} to 0"
    )
