"""Rebuild a rosbag2 MCAP bag cut off by a kill: the MCAP summary where it is missing, and
``metadata.yaml`` (what ``ros2 bag reindex`` and ``mcap recover`` do, without either).

A recorder killed with SIGKILL leaves its last storage file without summary and footer
(rosbags' MCAP writer, like rosbag2's, writes them at close) and the bag without
``metadata.yaml``; :class:`~uav_fusion.bag.writer.BagWriter` also leaves the open part in its
own sub-folder. Streaming readers still read such a file; rosbags and seeking readers refuse
it. :func:`reindex`:

1. finds the storage files: ``*.mcap`` in the bag folder and one level below (an open part);
2. keeps every file whose footer and summary read back (a seeking reader opens it);
3. reads every other file from the start, record by record, up to the first record that is
   not whole (a chunk cut in the middle is lost as a whole: its messages were not yet on disk
   as one piece); schemas, channels, messages and metadata records are written again, in
   order, into a complete MCAP (same chunk compression, summary with chunk indexes and
   statistics, a ``rosbag2`` metadata record), which replaces the file atomically; a file in a
   sub-folder moves up into the bag folder;
4. writes ``metadata.yaml`` (version 9, storage ``mcap``) from what the files hold: per file
   its start, duration and count; per topic its type, serialization format, offered QoS (from
   the channel's metadata), RIHS01 type hash (Jazzy type store, else the schema's own
   definition) and count. ``custom_data`` of a readable old ``metadata.yaml`` is kept.

What a killed recorder loses is what it had not flushed: ``bag_recorder`` closes its chunk
every ``flush_period`` seconds, so at most that much.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from uav_fusion.bag.writer import METADATA_VERSION, ensure_type, jazzy_typestore
from uav_fusion.core.errors import DataError

MAGIC = b"\x89MCAP0\r\n"


@dataclass
class FileReport:
    """What happened to one storage file."""

    path: Path  # where it is now
    status: str  # "complete" | "recovered" | "recovered (no message)" | "unreadable"
    messages: int
    lost_bytes: int = 0  # bytes after the last whole record (recovered files)
    note: str = ""


@dataclass
class _Topic:
    name: str
    msgtype: str
    encoding: str
    qos: Any
    schema_text: bytes = b""
    count: int = 0


@dataclass
class _FileInfo:
    path: Path
    count: int = 0
    start: int | None = None
    end: int | None = None
    topics: dict[str, _Topic] = field(default_factory=dict)

    def saw(self, topic: str, t: int) -> None:
        self.count += 1
        self.topics[topic].count += 1
        self.start = t if self.start is None else min(self.start, t)
        self.end = t if self.end is None else max(self.end, t)


@dataclass
class ReindexReport:
    """What :func:`reindex` did."""

    bag: Path
    files: list[FileReport]
    counts: dict[str, int]
    metadata: Path | None

    @property
    def message_count(self) -> int:
        return sum(self.counts.values())

    def summary(self) -> str:
        lines = []
        for f in self.files:
            extra = f", {f.lost_bytes} bytes after the last whole record dropped" \
                if f.lost_bytes else ""
            lines.append(f"{f.path.name}: {f.status}, {f.messages} messages{extra}"
                         + (f" ({f.note})" if f.note else ""))
        per_topic = ", ".join(f"{t} {n}" for t, n in sorted(self.counts.items()))
        lines.append(f"{self.message_count} messages: {per_topic or 'none'}")
        if self.metadata is not None:
            lines.append(f"wrote {self.metadata}")
        return "\n".join(lines)


def _natural(p: Path) -> list[Any]:
    return [int(s) if s.isdigit() else s for s in re.split(r"(\d+)", p.name)]


def storage_files(bag: Path) -> list[Path]:
    """The MCAP files of a bag folder (and of an open part one level below), in order."""
    top = sorted((p for p in bag.glob("*.mcap") if p.is_file()), key=_natural)
    sub = sorted((p for p in bag.glob("*/*.mcap") if p.is_file()), key=_natural)
    return top + sub


def is_complete(path: Path) -> bool:
    """Does the file end in a footer with a summary a seeking reader can use?"""
    from mcap.reader import SeekingReader

    try:
        with path.open("rb") as f:
            f.seek(-len(MAGIC), os.SEEK_END)
            if f.read(len(MAGIC)) != MAGIC:
                return False
            f.seek(0)
            summary = SeekingReader(f).get_summary()
            return summary is not None and summary.statistics is not None and bool(
                summary.chunk_indexes or not summary.statistics.message_count)
    except Exception:  # any parse error: not complete
        return False


def _qos_of(metadata: dict[str, str]) -> Any:
    text = metadata.get("offered_qos_profiles", "")
    try:
        value = yaml.safe_load(text) if text else []
    except yaml.YAMLError:
        return []
    return value if isinstance(value, list) else []


def _scan_complete(path: Path) -> _FileInfo:
    """Topics and counts of a complete file, from its summary and messages."""
    from mcap.reader import SeekingReader

    info = _FileInfo(path)
    with path.open("rb") as f:
        reader = SeekingReader(f)
        summary = reader.get_summary()
        assert summary is not None
        for ch in summary.channels.values():
            sc = summary.schemas.get(ch.schema_id)
            info.topics[ch.topic] = _Topic(
                ch.topic, sc.name if sc else "", ch.message_encoding, _qos_of(ch.metadata),
                sc.data if sc else b"")
        for _schema, channel, message in reader.iter_messages(log_time_order=False):
            info.saw(channel.topic, message.log_time)
    return info


def _recover(path: Path, dest: Path) -> tuple[_FileInfo, int]:
    """Rewrite the readable prefix of ``path`` as a complete MCAP at ``dest``; the file's
    info and the number of bytes that could not be read."""
    from mcap.records import Channel, Chunk, Header, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader, breakup_chunk
    from mcap.writer import CompressionType, Writer

    size = path.stat().st_size
    info = _FileInfo(dest)
    schemas: dict[int, tuple[int, Schema]] = {}
    channels: dict[int, int] = {}
    topic_of: dict[int, str] = {}
    metadata: list[Metadata] = []
    profile, library = "ros2", ""
    compression: str | None = None
    good_end = 0
    tmp = dest.with_name(dest.name + ".reindex.tmp")
    writer: Writer | None = None
    out = tmp.open("wb")

    def ensure_writer() -> Writer:
        nonlocal writer
        if writer is None:
            comp = {"": CompressionType.NONE, "zstd": CompressionType.ZSTD,
                    "lz4": CompressionType.LZ4}.get(compression or "", CompressionType.NONE)
            writer = Writer(out, compression=comp)
            writer.start(profile, f"uav_fusion bag reindex; written by {library or '?'}")
        return writer

    def take(rec: Any) -> None:
        if isinstance(rec, Schema):
            if rec.id not in schemas:
                new = ensure_writer().register_schema(rec.name, rec.encoding, rec.data)
                schemas[rec.id] = (new, rec)
        elif isinstance(rec, Channel):
            if rec.id not in channels:
                sid = schemas[rec.schema_id][0] if rec.schema_id in schemas else 0
                channels[rec.id] = ensure_writer().register_channel(
                    rec.topic, rec.message_encoding, sid, dict(rec.metadata))
                topic_of[rec.id] = rec.topic
                sc = schemas.get(rec.schema_id)
                info.topics.setdefault(rec.topic, _Topic(
                    rec.topic, sc[1].name if sc else "", rec.message_encoding,
                    _qos_of(rec.metadata), sc[1].data if sc else b""))
        elif isinstance(rec, Message):
            if rec.channel_id not in channels:
                return  # a message of a channel never declared: unreadable
            ensure_writer().add_message(channels[rec.channel_id],
                                        rec.log_time, rec.data, rec.publish_time, rec.sequence)
            info.saw(topic_of[rec.channel_id], rec.log_time)
        elif isinstance(rec, Metadata) and rec.name != "rosbag2":
            metadata.append(rec)

    try:
        with path.open("rb") as f:
            reader = StreamReader(f, emit_chunks=True, record_size_limit=size)
            try:
                for rec in reader.records:
                    if isinstance(rec, Header):
                        profile, library = rec.profile or "ros2", rec.library
                    elif isinstance(rec, Chunk):
                        recs = breakup_chunk(rec)
                        if compression is None:
                            compression = rec.compression
                        for r in recs:
                            take(r)
                    else:
                        take(rec)
                    good_end = f.tell()
            except Exception:  # the first record that is not whole ends the readable part
                pass
        if not info.topics:  # not one whole record: leave the file as it is
            out.close()
            tmp.unlink(missing_ok=True)
            return info, size
        w = ensure_writer()
        for m in metadata:
            w.add_metadata(m.name, dict(m.metadata))
        info.path = dest
        w.add_metadata("rosbag2", {"serialized_metadata": yaml.safe_dump(
            _bag_info([info], {}), default_flow_style=False, sort_keys=False).strip()})
        w.finish()
        out.flush()
        os.fsync(out.fileno())
    except BaseException:
        out.close()
        tmp.unlink(missing_ok=True)
        raise
    out.close()
    tmp.replace(dest)
    if dest != path:
        path.unlink()
    return info, max(0, size - good_end)


def _type_hash(store: Any, t: _Topic) -> str:
    """RIHS01 of a topic's type: from the Jazzy type store (installed .msg files), else from
    the schema's own definitions."""
    if not t.msgtype:
        return ""
    try:
        ensure_type(store, t.msgtype)
    except DataError:
        try:
            _register_from_schema(store, t.msgtype, t.schema_text.decode("utf-8"))
        except Exception:
            return ""
    try:
        return str(store.hash_rihs01(t.msgtype))
    except Exception:
        return ""


def _register_from_schema(store: Any, msgtype: str, text: str) -> None:
    """Register the definitions of a ``ros2msg`` schema (the main type, then ``MSG: name``
    sections separated by lines of ``=``)."""
    from rosbags.typesys import get_types_from_msg

    parts = re.split(r"^=+\s*$", text, flags=re.MULTILINE)
    types: dict[str, Any] = dict(get_types_from_msg(parts[0], msgtype))
    for part in parts[1:]:
        body = part.strip("\n")
        head, _, rest = body.partition("\n")
        if head.startswith("MSG: "):
            name = head[len("MSG: "):].strip()
            if "/msg/" not in name and "/" in name:
                pkg, _, base = name.partition("/")
                name = f"{pkg}/msg/{base}"
            types.update(get_types_from_msg(rest, name))
    store.register(types)


def _bag_info(files: list[_FileInfo], custom: dict[str, str]) -> dict[str, Any]:
    """``rosbag2_bagfile_information`` of ``files``."""
    store = jazzy_typestore()
    topics: dict[str, _Topic] = {}
    counts: Counter[str] = Counter()
    for fi in files:
        for name, t in fi.topics.items():
            topics.setdefault(name, t)
            counts[name] += t.count
    starts = [fi.start for fi in files if fi.start is not None]
    ends = [fi.end for fi in files if fi.end is not None]
    start = min(starts) if starts else 0
    entries = []
    for fi in files:
        s = fi.start or 0
        entries.append({
            "path": fi.path.name,
            "starting_time": {"nanoseconds_since_epoch": s},
            "duration": {"nanoseconds": (fi.end - s) if fi.end is not None else 0},
            "message_count": fi.count,
        })
    info: dict[str, Any] = {
        "version": METADATA_VERSION,
        "storage_identifier": "mcap",
        "relative_file_paths": [e["path"] for e in entries],
        "duration": {"nanoseconds": (max(ends) - start) if ends else 0},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": sum(counts.values()),
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": t.name,
                    "type": t.msgtype,
                    "serialization_format": t.encoding,
                    "offered_qos_profiles": t.qos,
                    "type_description_hash": _type_hash(store, t),
                },
                "message_count": counts[t.name],
            }
            for t in topics.values()
        ],
        "compression_format": "",
        "compression_mode": "",
        "files": entries,
        "custom_data": custom or None,
        "ros_distro": "jazzy",
    }
    return info


def _old_custom(bag: Path) -> dict[str, str]:
    try:
        doc = yaml.safe_load((bag / "metadata.yaml").read_text(encoding="utf-8"))
        custom = doc["rosbag2_bagfile_information"].get("custom_data") or {}
        return {str(k): str(v) for k, v in custom.items()}
    except Exception:  # missing or unreadable: nothing to keep
        return {}


def reindex(
    bag: str | Path, *, dry_run: bool = False, log: Callable[[str], None] | None = None
) -> ReindexReport:
    """Rebuild ``bag`` (see the module text). ``dry_run``: only say what would be done.
    Raises DataError when ``bag`` is not a folder or holds no MCAP file."""
    bag = Path(bag)
    say = log or (lambda _t: None)
    if not bag.exists():
        raise DataError(bag, None, "no such bag folder")
    if not bag.is_dir():
        raise DataError(bag, None, "not a folder: give the bag folder (it holds the .mcap files)")
    files = storage_files(bag)
    if not files:
        if list(bag.glob("*.db3")):
            raise DataError(bag, None, "a sqlite3 bag: reindex rebuilds MCAP bags only")
        raise DataError(bag, None, "no .mcap file in this folder or its sub-folders")
    reports: list[FileReport] = []
    infos: list[_FileInfo] = []
    for path in files:
        dest = bag / path.name if path.parent != bag else path
        if dest != path and dest.exists():
            raise DataError(path, None, f"cannot move it up: {dest} exists")
        if is_complete(path):
            info = _scan_complete(path)
            if dest != path and not dry_run:
                # a part the recorder had just closed in its own folder when it stopped
                path.replace(dest)
                info.path = dest
                _remove_part_dir(path.parent)
            reports.append(FileReport(dest, "complete", info.count))
            infos.append(info)
            say(f"{path.name}: complete, {info.count} messages")
            continue
        if dry_run:
            reports.append(FileReport(path, "needs recovery", 0))
            continue
        info, lost = _recover(path, dest)
        if info.topics:
            status = "recovered" if info.count else "recovered (no message)"
            reports.append(FileReport(dest, status, info.count, lost))
            infos.append(info)
            if path.parent != bag:
                _remove_part_dir(path.parent)
        else:
            # not one whole record (killed before its first flush, or not an MCAP): kept
            # aside under another name, out of the bag's files
            aside = bag / (path.name + ".unreadable")
            path.replace(aside)
            reports.append(FileReport(aside, "unreadable", 0, lost,
                                      "no whole record: nothing of it was flushed; set aside"))
            if path.parent != bag:
                _remove_part_dir(path.parent)
        say(f"{path.name}: {reports[-1].status}, {info.count} messages, {lost} bytes dropped")
    if not infos and not dry_run:
        raise DataError(bag, None, "no file holds a whole record (nothing was flushed before "
                        "the recorder stopped); the files were set aside as *.unreadable")
    counts: Counter[str] = Counter()
    for fi in infos:
        for name, t in fi.topics.items():
            counts[name] += t.count
    meta: Path | None = None
    if not dry_run:
        doc = {"rosbag2_bagfile_information": _bag_info(infos, _old_custom(bag))}
        meta = bag / "metadata.yaml"
        tmp = bag / "metadata.yaml.tmp"
        tmp.write_text(yaml.safe_dump(doc, default_flow_style=False, sort_keys=False),
                       encoding="utf-8")
        tmp.replace(meta)
    return ReindexReport(bag, reports, dict(counts), meta)


def _remove_part_dir(folder: Path) -> None:
    """Remove an open part's folder once its file moved up (nothing else of value in it)."""
    leftovers = [p for p in folder.iterdir() if p.suffix not in (".yaml", ".tmp")]
    if not leftovers:
        shutil.rmtree(folder, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            folder.rmdir()
