"""Read rosbag2 bags (a bag directory, a bare ``.mcap`` or a bare ``.db3``) as raw CDR messages.

No single reader is trusted. For a bag directory with a readable ``metadata.yaml`` the reader
first tries rosbags; it counts what rosbags actually yields per topic and compares that with the
counts in ``metadata.yaml``. When they differ (some real rosbag2 bags open fine in rosbags yet
yield no messages), the storage files are read directly: ``.mcap`` with the ``mcap`` library's
linear stream reader, ``.db3`` with ``sqlite3``. The backend that yields the most messages wins,
and every disagreement is reported in :attr:`BagReader.warnings`.

Damaged input never raises a traceback: a truncated ``.mcap`` yields its readable prefix with a
warning; a missing or corrupt ``metadata.yaml`` falls back to the storage files found in the
directory. Only input with nothing readable at all raises :class:`DataError`.

Messages are never decoded here; they are handed out as the CDR bytes stored in the bag.
"""

from __future__ import annotations

import heapq
import sqlite3
from collections import Counter
from collections.abc import Callable, Collection, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from uav_fusion.core.errors import DataError

STORAGE_SUFFIXES = {".mcap": "mcap", ".db3": "sqlite3"}


@dataclass(frozen=True)
class BagTopic:
    """One topic (connection) of a bag."""

    name: str
    msgtype: str  # e.g. "geometry_msgs/msg/PointStamped"
    serialization_format: str = "cdr"
    offered_qos: tuple[dict[str, Any], ...] = ()  # as recorded, parsed; may be empty
    msgdef: str = ""  # message definition text when the storage carries one
    count: int = 0  # messages actually readable by the chosen backend


@dataclass(frozen=True)
class RawMessage:
    """One stored message: topic, receive (log) time in ns, CDR bytes."""

    topic: str
    timestamp_ns: int
    data: bytes


@dataclass
class BagMetadata:
    """The parts of ``metadata.yaml`` the reader relies on."""

    version: int
    storage: str
    files: list[str]
    message_count: int
    topic_counts: dict[str, int]
    topics: list[BagTopic]


@dataclass
class _Scan:
    counts: Counter[str] = field(default_factory=Counter)
    topics: dict[str, BagTopic] = field(default_factory=dict)
    first_ns: int | None = None
    last_ns: int | None = None
    error: str | None = None

    @property
    def total(self) -> int:
        return sum(self.counts.values())


def parse_qos(value: object) -> tuple[dict[str, Any], ...]:
    """QoS profiles as stored in metadata.yaml or an MCAP channel: a YAML string (v4..v8) or a
    list of mappings (v9). Unparseable input gives ``()``."""
    if isinstance(value, str):
        if not value.strip():
            return ()
        try:
            value = yaml.safe_load(value)
        except yaml.YAMLError:
            return ()
    if isinstance(value, list):
        return tuple(v for v in value if isinstance(v, dict))
    return ()


def qos_reliability(profiles: tuple[dict[str, Any], ...]) -> str | None:
    """"reliable", "best_effort" or None from recorded QoS profiles (any entry best effort wins,
    as then a reliable reader would not have matched every writer)."""
    kinds = set()
    for p in profiles:
        r = p.get("reliability")
        if r in (1, "reliable"):
            kinds.add("reliable")
        elif r in (2, "best_effort"):
            kinds.add("best_effort")
    if "best_effort" in kinds:
        return "best_effort"
    return "reliable" if kinds else None


def qos_transient_local(profiles: tuple[dict[str, Any], ...]) -> bool:
    """True when every recorded publisher offered transient-local durability."""
    if not profiles:
        return False
    return all(p.get("durability") in (1, "transient_local") for p in profiles)


def _load_metadata(path: Path) -> BagMetadata:
    """Parse ``metadata.yaml``; raises DataError naming what is wrong."""
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(path, None, f"cannot read: {exc}") from None
    except ValueError:  # PyYAML's int() of an integer beyond Python's 4300-digit limit
        raise DataError(path, None, "not valid YAML (an integer with too many digits)") from None
    except yaml.YAMLError as exc:
        line = None
        mark = getattr(exc, "problem_mark", None)
        if mark is not None:
            line = int(mark.line) + 1
        raise DataError(path, line, f"not valid YAML ({getattr(exc, 'problem', exc)})") from None
    info = doc.get("rosbag2_bagfile_information") if isinstance(doc, dict) else None
    if not isinstance(info, dict):
        raise DataError(path, None, "no 'rosbag2_bagfile_information' mapping")
    try:
        files = [str(f) for f in info["relative_file_paths"]]
        topics: list[BagTopic] = []
        counts: dict[str, int] = {}
        for entry in info.get("topics_with_message_count") or []:
            meta = entry["topic_metadata"]
            name = str(meta["name"])
            counts[name] = int(entry.get("message_count", 0))
            topics.append(
                BagTopic(
                    name=name,
                    msgtype=str(meta["type"]),
                    serialization_format=str(meta.get("serialization_format", "cdr")),
                    offered_qos=parse_qos(meta.get("offered_qos_profiles", "")),
                    count=counts[name],
                )
            )
        return BagMetadata(
            version=int(info.get("version", 0)),
            storage=str(info.get("storage_identifier", "")),
            files=files,
            message_count=int(info.get("message_count", sum(counts.values()))),
            topic_counts=counts,
            topics=topics,
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise DataError(path, None, f"malformed rosbag2 metadata ({exc!r})") from None


# --------------------------------------------------------------------------- backends
# Each backend is a function (selected topics or None) -> iterator of RawMessage, which also
# fills a topic table as it learns topics. Backends raise on damage; callers decide.

_MessageSource = Callable[[Collection[str] | None, dict[str, BagTopic]], Iterator[RawMessage]]


def _rosbags_source(bag_dir: Path) -> _MessageSource:
    def source(
        topics: Collection[str] | None, table: dict[str, BagTopic]
    ) -> Iterator[RawMessage]:
        from rosbags.rosbag2 import Reader

        with Reader(bag_dir) as reader:
            conns = []
            for c in reader.connections:
                ext = c.ext
                table.setdefault(
                    c.topic,
                    BagTopic(
                        name=c.topic,
                        msgtype=c.msgtype,
                        serialization_format=str(getattr(ext, "serialization_format", "cdr")),
                        offered_qos=_rosbags_qos(getattr(ext, "offered_qos_profiles", ())),
                        msgdef=c.msgdef.data if c.msgdef else "",
                    ),
                )
                if topics is None or c.topic in topics:
                    conns.append(c)
            if not conns:
                return
            for conn, stamp, data in reader.messages(connections=conns):
                yield RawMessage(conn.topic, int(stamp), bytes(data))

    return source


def _rosbags_qos(profiles: object) -> tuple[dict[str, Any], ...]:
    out = []
    for q in profiles if isinstance(profiles, list | tuple) else ():
        try:
            out.append(
                {
                    "reliability": q.reliability.name.lower(),
                    "durability": q.durability.name.lower(),
                    "history": q.history.name.lower(),
                    "depth": int(q.depth),
                }
            )
        except AttributeError:
            continue
    return tuple(out)


def _mcap_file_messages(
    path: Path, topics: Collection[str] | None, table: dict[str, BagTopic]
) -> Iterator[RawMessage]:
    """Linear read of one MCAP file, in file order; raises at the first damaged record."""
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader

    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    with path.open("rb") as fh:
        for record in StreamReader(fh, validate_crcs=True).records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
                schema = schemas.get(record.schema_id)
                if record.topic not in table:
                    table[record.topic] = BagTopic(
                        name=record.topic,
                        msgtype=schema.name if schema else "",
                        serialization_format=record.message_encoding or "cdr",
                        offered_qos=parse_qos(record.metadata.get("offered_qos_profiles", "")),
                        msgdef=schema.data.decode("utf-8", "replace") if schema else "",
                    )
            elif isinstance(record, Message):
                chan = channels.get(record.channel_id)
                if chan is None:
                    continue  # a message before its channel: unusable
                if topics is None or chan.topic in topics:
                    yield RawMessage(chan.topic, int(record.log_time), bytes(record.data))


def _sqlite_file_messages(
    path: Path, topics: Collection[str] | None, table: dict[str, BagTopic]
) -> Iterator[RawMessage]:
    """All messages of one rosbag2 sqlite3 file in timestamp order."""
    con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        cols = {row[1] for row in con.execute("PRAGMA table_info(topics)")}
        if not cols:
            raise DataError(path, None, "no 'topics' table: not a rosbag2 sqlite3 file")
        qos_col = "offered_qos_profiles" if "offered_qos_profiles" in cols else "''"
        ids: dict[int, str] = {}
        for tid, name, typ, fmt, qos in con.execute(
            f"SELECT id, name, type, serialization_format, {qos_col} FROM topics"
        ):
            ids[int(tid)] = str(name)
            table.setdefault(
                str(name),
                BagTopic(
                    name=str(name),
                    msgtype=str(typ),
                    serialization_format=str(fmt),
                    offered_qos=parse_qos(qos),
                ),
            )
        cursor = con.execute(
            "SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id"
        )
        for tid, stamp, data in cursor:
            name = ids.get(int(tid))
            if name is None:
                continue
            if topics is None or name in topics:
                yield RawMessage(name, int(stamp), bytes(data))
    finally:
        con.close()


def _files_source(files: list[Path]) -> _MessageSource:
    def source(
        topics: Collection[str] | None, table: dict[str, BagTopic]
    ) -> Iterator[RawMessage]:
        streams: list[Iterator[RawMessage]] = []
        for f in files:
            if f.suffix == ".mcap":
                streams.append(_mcap_file_messages(f, topics, table))
            else:
                streams.append(_sqlite_file_messages(f, topics, table))
        if len(streams) == 1:
            yield from streams[0]
        else:
            yield from heapq.merge(*streams, key=lambda m: m.timestamp_ns)

    return source


def _storage_counts(files: list[Path]) -> Counter[str] | None:
    """Messages per topic as the storage files themselves count them, cheaply: the sqlite3
    ``messages`` table, the MCAP summary statistics. None when a file has no usable count
    (an MCAP without summary, a damaged file)."""
    counts: Counter[str] = Counter()
    try:
        for f in files:
            if f.suffix == ".db3":
                con = sqlite3.connect(f"file:{f}?mode=ro", uri=True)
                try:
                    rows = con.execute(
                        "SELECT t.name, COUNT(*) FROM messages m JOIN topics t "
                        "ON m.topic_id = t.id GROUP BY t.name"
                    ).fetchall()
                finally:
                    con.close()
                for name, n in rows:
                    counts[str(name)] += int(n)
            else:
                from mcap.reader import make_reader

                with f.open("rb") as fh:
                    summary = make_reader(fh).get_summary()
                if summary is None or summary.statistics is None:
                    return None
                for cid, n in summary.statistics.channel_message_counts.items():
                    channel = summary.channels.get(cid)
                    if channel is None:
                        return None
                    counts[channel.topic] += int(n)
    except Exception:  # a damaged file: no cheap count
        return None
    return counts


def _scan(source: _MessageSource) -> _Scan:
    scan = _Scan()
    try:
        for msg in source(None, scan.topics):
            scan.counts[msg.topic] += 1
            if scan.first_ns is None or msg.timestamp_ns < scan.first_ns:
                scan.first_ns = msg.timestamp_ns
            if scan.last_ns is None or msg.timestamp_ns > scan.last_ns:
                scan.last_ns = msg.timestamp_ns
    except Exception as exc:  # damaged storage: keep the readable prefix
        scan.error = f"{type(exc).__name__}: {exc}".strip()
    return scan


# --------------------------------------------------------------------------- public reader


class BagReader:
    """A rosbag2 bag opened for raw reading.

    ``BagReader(path)`` accepts a bag directory, a bare ``.mcap`` or a bare ``.db3`` file. Opening
    scans the whole bag once (no decoding) to learn what is really readable; afterwards
    :attr:`topics` carries per-topic readable counts and :attr:`warnings` every problem found.
    Raises :class:`DataError` when the path does not exist or holds nothing readable.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.warnings: list[str] = []
        self.metadata: BagMetadata | None = None
        self.files: list[Path] = self._locate()
        self.storage = STORAGE_SUFFIXES[self.files[0].suffix]
        self.backend, self._source, scan = self._choose_backend()
        meta_topics: dict[str, BagTopic] = (
            {t.name: t for t in self.metadata.topics} if self.metadata else {}
        )
        self.topics: dict[str, BagTopic] = {}
        for name in [*meta_topics, *(n for n in scan.topics if n not in meta_topics)]:
            base = scan.topics.get(name) or meta_topics[name]
            meta = meta_topics.get(name)
            self.topics[name] = BagTopic(
                name=name,
                msgtype=base.msgtype or (meta.msgtype if meta else ""),
                serialization_format=base.serialization_format,
                offered_qos=base.offered_qos or (meta.offered_qos if meta else ()),
                msgdef=base.msgdef,
                count=scan.counts.get(name, 0),
            )
        self.message_count = scan.total
        self.start_ns = scan.first_ns or 0
        self.end_ns = scan.last_ns or 0
        if self.message_count == 0:
            self.warnings.append(f"{self.path}: the bag holds no readable messages")

    # -- opening -----------------------------------------------------------------------------

    def _locate(self) -> list[Path]:
        p = self.path
        if not p.exists():
            raise DataError(p, None, "no such bag (expected a bag directory, .mcap or .db3)")
        if p.is_file():
            if p.suffix not in STORAGE_SUFFIXES:
                raise DataError(p, None, "not a bag: expected a directory, .mcap or .db3 file")
            return [p]
        meta_path = p / "metadata.yaml"
        if meta_path.is_file():
            try:
                self.metadata = _load_metadata(meta_path)
            except DataError as exc:
                self.warnings.append(f"{exc}; reading the storage files directly")
        else:
            self.warnings.append(f"{meta_path}: missing; reading the storage files directly")
        files: list[Path] = []
        if self.metadata is not None:
            for rel in self.metadata.files:
                f = p / rel
                if f.suffix not in STORAGE_SUFFIXES:
                    # compressed or foreign storage: we read only plain .mcap / .db3
                    self.warnings.append(f"{f}: unsupported storage file, skipped")
                elif not f.is_file():
                    self.warnings.append(f"{f}: listed in metadata.yaml but missing")
                else:
                    files.append(f)
        if not files:
            files = sorted(f for f in p.iterdir() if f.suffix in STORAGE_SUFFIXES)
            if not files:  # an interrupted split recording keeps its open part in a subfolder
                files = sorted(f for f in p.rglob("*") if f.suffix in STORAGE_SUFFIXES)
            if files and self.metadata is not None:
                self.warnings.append(
                    f"{p}: using storage files found in the directory: "
                    + ", ".join(str(f.relative_to(p)) for f in files)
                )
        if not files:
            raise DataError(p, None, "bag directory holds no .mcap or .db3 storage file")
        kinds = {f.suffix for f in files}
        if len(kinds) > 1:
            db3 = self.metadata is not None and self.metadata.storage == "sqlite3"
            keep = ".db3" if db3 else ".mcap"
            self.warnings.append(f"{p}: mixed storage files; reading only {keep}")
            files = [f for f in files if f.suffix == keep]
        return files

    def _choose_backend(self) -> tuple[str, _MessageSource, _Scan]:
        meta = self.metadata
        expected = meta.topic_counts if meta else None
        candidates: list[tuple[str, _MessageSource]] = []
        if meta is not None and self.path.is_dir():
            candidates.append(("rosbags", _rosbags_source(self.path)))
        direct = "mcap" if self.storage == "mcap" else "sqlite3"
        candidates.append((direct, _files_source(self.files)))

        best: tuple[str, _MessageSource, _Scan] | None = None
        for name, source in candidates:
            scan = _scan(source)
            ok = scan.error is None and (
                meta is None
                or (_same_counts(scan.counts, meta.topic_counts)
                    and scan.total == meta.message_count)
            )
            if scan.error is not None:
                self.warnings.append(
                    f"{self.path}: {name} reader stopped after {scan.total} messages "
                    f"({scan.error}); the readable prefix is used"
                )
            elif not ok:
                self.warnings.append(
                    f"{self.path}: {name} reader yields {scan.total} messages, "
                    f"metadata.yaml lists {meta.message_count if meta else '?'}"
                )
            if ok and name == "rosbags":
                # rosbags reads the topics metadata.yaml lists: a topic missing there would be
                # lost without a word; cross-check with what the storage files hold
                held = _storage_counts(self.files)
                if held is None:
                    held = _scan(_files_source(self.files)).counts
                if +held != +scan.counts:
                    diff = ", ".join(
                        f"{t}: {held.get(t, 0)} stored, {scan.counts.get(t, 0)} read"
                        for t in sorted(set(held) | set(scan.counts))
                        if held.get(t, 0) != scan.counts.get(t, 0)
                    )
                    self.warnings.append(
                        f"{self.path}: metadata.yaml does not describe the storage files "
                        f"({diff}); reading the storage files directly"
                    )
                    ok = False
            if best is None or scan.total > best[2].total:
                best = (name, source, scan)
            if ok:
                return name, source, scan
        assert best is not None
        if expected is not None and not _same_counts(best[2].counts, expected):
            got = best[2].counts
            diff = ", ".join(
                f"{t}: {got.get(t, 0)} of {expected.get(t, 0)}"
                for t in sorted(set(expected) | set(got))
                if got.get(t, 0) != expected.get(t, 0)
            )
            self.warnings.append(
                f"{self.path}: message counts differ from metadata.yaml ({diff}); "
                f"playing what the {best[0]} reader yields"
            )
        return best

    # -- reading -----------------------------------------------------------------------------

    def messages(
        self,
        topics: Collection[str] | None = None,
        start_ns: int | None = None,
        end_ns: int | None = None,
    ) -> Iterator[RawMessage]:
        """Raw messages (optionally only ``topics``, ``start_ns <= t < end_ns``), in stored time
        order. A damaged tail ends the iteration quietly (it was reported when opening)."""
        wanted = None if topics is None else set(topics)
        table: dict[str, BagTopic] = {}
        try:
            for msg in self._source(wanted, table):
                if start_ns is not None and msg.timestamp_ns < start_ns:
                    continue
                if end_ns is not None and msg.timestamp_ns >= end_ns:
                    continue
                yield msg
        except Exception:  # damage was reported once, at open
            return

    def summary(self) -> str:
        """One line per topic: name, type, readable count."""
        lines = [
            f"{self.path}: {self.message_count} messages, {len(self.topics)} topics, "
            f"{(self.end_ns - self.start_ns) / 1e9:.3f} s, storage {self.storage}, "
            f"read with {self.backend}"
        ]
        for t in self.topics.values():
            lines.append(f"  {t.name} [{t.msgtype}] {t.count}")
        return "\n".join(lines)


def _same_counts(got: Counter[str], expected: dict[str, int]) -> bool:
    return all(got.get(t, 0) == n for t, n in expected.items()) and all(
        t in expected for t in got
    )
