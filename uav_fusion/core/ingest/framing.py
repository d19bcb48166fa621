"""Bytes to lines: the framing every transport shares.

A line ends at ``\\n``; a ``\\r`` before it is dropped (CRLF senders). A UTF-8 byte-order
mark at the very start of a stream is dropped. A line longer than ``max_bytes`` is never
buffered whole: its bytes are discarded up to the next ``\\n`` and the line is counted once as
``too_long``. What arrives without a final ``\\n`` stays pending until the rest comes (a
half-written line); :meth:`LineFramer.cut` ends a stream (a dropped connection, a rotated or
truncated file) and reports whether a partial line was lost.
"""

from __future__ import annotations

BOM = b"\xef\xbb\xbf"


class LineFramer:
    """Splits a byte stream into lines (see the module text)."""

    def __init__(self, max_bytes: int) -> None:
        if max_bytes < 1:
            raise ValueError("max_bytes must be >= 1")
        self.max_bytes = int(max_bytes)
        self._buf = bytearray()
        self._skipping = False  # inside a line already counted as too long
        self._start = True  # nothing seen yet on this stream (a BOM may follow)
        #: lines discarded as longer than ``max_bytes``
        self.too_long = 0

    @property
    def pending(self) -> int:
        """Bytes of an unfinished line held back."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[bytes]:
        """The complete lines ``data`` finishes (without line ends), in order."""
        if self._start and data:
            if len(self._buf) + len(data) < len(BOM) and BOM.startswith(bytes(self._buf) + data):
                self._buf += data
                return []
            data = bytes(self._buf) + data
            self._buf.clear()
            if data.startswith(BOM):
                data = data[len(BOM):]
            self._start = False
        out: list[bytes] = []
        pos = 0
        n = len(data)
        while pos < n:
            nl = data.find(b"\n", pos)
            end = n if nl < 0 else nl
            if self._skipping:
                if nl >= 0:
                    self._skipping = False
                pos = end + 1
                continue
            size = len(self._buf) + (end - pos)
            if size > self.max_bytes:
                self.too_long += 1
                self._buf.clear()
                self._skipping = nl < 0
                pos = end + 1
                continue
            if nl < 0:
                self._buf += data[pos:]
                break
            if self._buf:
                self._buf += data[pos:end]
                line = bytes(self._buf)
                self._buf.clear()
            else:
                line = data[pos:end]
            if line.endswith(b"\r"):
                line = line[:-1]
            out.append(line)
            pos = end + 1
        return out

    def cut(self) -> bool:
        """The stream ended: forget an unfinished line; True if one was pending. The next
        bytes start a new stream (a BOM may come again)."""
        lost = bool(self._buf) and not self._skipping
        self._buf.clear()
        self._skipping = False
        self._start = True
        return lost

    def flush_datagram(self) -> list[bytes]:
        """End of a datagram: a last line without ``\\n`` is complete (UDP senders)."""
        if self._skipping:
            self._skipping = False
            return []
        if not self._buf:
            return []
        line = bytes(self._buf)
        self._buf.clear()
        if line.endswith(b"\r"):
            line = line[:-1]
        return [line]
