"""Write rosbag2 MCAP bags with rosbags, optionally split by size or duration.

:class:`BagWriter` takes raw CDR messages (as a recorder receives them) and writes a rosbag2
bag directory: ``<name>_0.mcap``, ``<name>_1.mcap``, ... plus one ``metadata.yaml`` describing
all of them (metadata version 9, storage ``mcap``). Each storage file is written by
``rosbags.rosbag2.Writer``, so message definitions and RIHS01 type hashes are the ones of
rosbags' ROS 2 Jazzy type store, which match the live Jazzy graph.

While a part is open it lives in ``<bag>/<name>_<k>/``; closing a part moves its ``.mcap`` up
into the bag directory. A writer killed without closing leaves at most that last part without
an index; :class:`uav_fusion.bag.reader.BagReader` still reads its readable prefix.
"""

from __future__ import annotations

import shutil
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import yaml

from uav_fusion.core.errors import ConfigError, DataError

METADATA_VERSION: Literal[9] = 9


def jazzy_typestore() -> Any:
    """rosbags' type store for ROS 2 Jazzy."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def _msg_file(msgtype: str) -> Path | None:
    pkg, _, name = msgtype.partition("/msg/")
    if not name:
        return None
    roots = [Path(sys.prefix) / "share" / pkg]
    try:
        from ament_index_python.packages import get_package_share_directory

        roots.insert(0, Path(get_package_share_directory(pkg)))
    except Exception:  # package not in any ament index
        pass
    for root in roots:
        f = root / "msg" / f"{name}.msg"
        if f.is_file():
            return f
    return None


def ensure_type(typestore: Any, msgtype: str) -> None:
    """Make ``msgtype`` known to ``typestore``: from the store itself, else from the ``.msg``
    files of installed packages (dependencies included). Raises DataError when no definition
    can be found."""
    from rosbags.typesys import get_types_from_msg

    pending = [msgtype]
    seen: set[str] = set()
    while pending:
        t = pending.pop()
        if t in typestore.fielddefs or t in seen:
            continue
        seen.add(t)
        f = _msg_file(t)
        if f is None:
            raise DataError(
                None, None, f"message type {t}: not in the Jazzy type store and no installed .msg"
            )
        types = get_types_from_msg(f.read_text(encoding="utf-8"), t)
        for fields in types.values():
            for _fname, desc in fields[1]:
                for sub in _nested_names(desc):
                    if sub not in typestore.fielddefs:
                        pending.append(sub)
        typestore.register(types)


def _nested_names(desc: Any) -> list[str]:
    # rosbags field descriptors: (Nodetype, payload); NAME payload is the type name,
    # ARRAY / SEQUENCE payload is ((Nodetype, payload), size)
    out: list[str] = []
    kind, payload = desc
    name = getattr(kind, "name", "")
    if name == "NAME" and isinstance(payload, str):
        out.append(payload)
    elif name in {"ARRAY", "SEQUENCE"}:
        out.extend(_nested_names(payload[0]))
    return out


@dataclass
class _TopicSpec:
    name: str
    msgtype: str
    qos: list[Any] = field(default_factory=list)  # rosbags Qos objects


@dataclass
class WrittenBag:
    """What :meth:`BagWriter.close` wrote."""

    path: Path
    files: list[Path]
    counts: dict[str, int]

    @property
    def message_count(self) -> int:
        return sum(self.counts.values())


class BagWriter:
    """Raw-message rosbag2 MCAP writer with optional splitting.

    ``max_bytes``: start a new file once the current one reaches this many bytes of message
    payload (0: never). ``max_duration_s``: start a new file once the current one spans this
    much bag time (0: never). The directory ``path`` must not exist yet.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        max_bytes: int = 0,
        max_duration_s: float = 0.0,
        typestore: Any | None = None,
    ) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise ConfigError(f"{self.path}: exists already; a bag is never overwritten")
        if max_bytes < 0 or max_duration_s < 0:
            raise ConfigError("split limits must be >= 0")
        self.max_bytes = int(max_bytes)
        self.max_duration_ns = int(max_duration_s * 1e9)
        self.typestore = typestore if typestore is not None else jazzy_typestore()
        self._topics: dict[str, _TopicSpec] = {}
        self._conns: dict[str, Any] = {}
        self._writer: Any | None = None
        self._part = -1
        self._part_bytes = 0
        self._part_start_ns: int | None = None
        self._parts: list[tuple[Path, dict[str, Any]]] = []  # (file, its metadata)
        self.counts: dict[str, int] = {}
        self.closed = False
        self.path.mkdir(parents=True)

    # -- topics ------------------------------------------------------------------------------

    def add_topic(
        self, name: str, msgtype: str, *, qos: Sequence[dict[str, Any]] = ()
    ) -> None:
        """Declare a topic before writing to it. ``qos``: offered profiles as mappings with
        ``reliability``/``durability``/``history``/``depth`` (names or rosbag2 enum numbers)."""
        if name in self._topics:
            if self._topics[name].msgtype != msgtype:
                raise DataError(None, None, f"topic {name}: type {msgtype} after "
                                f"{self._topics[name].msgtype}")
            return
        ensure_type(self.typestore, msgtype)
        spec = _TopicSpec(name, msgtype, [_to_rosbags_qos(q) for q in qos])
        self._topics[name] = spec
        self.counts[name] = 0
        if self._writer is not None:
            self._add_connection(spec)

    def _add_connection(self, spec: _TopicSpec) -> None:
        assert self._writer is not None
        self._conns[spec.name] = self._writer.add_connection(
            spec.name,
            spec.msgtype,
            typestore=self.typestore,
            serialization_format="cdr",
            offered_qos_profiles=spec.qos,
        )

    # -- parts -------------------------------------------------------------------------------

    def _part_dir(self, k: int) -> Path:
        return self.path / f"{self.path.name}_{k}"

    def _open_part(self) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        self._part += 1
        self._writer = Writer(
            self._part_dir(self._part), version=METADATA_VERSION, storage_plugin=StoragePlugin.MCAP
        )
        self._writer.open()
        self._conns = {}
        for spec in self._topics.values():
            self._add_connection(spec)
        self._part_bytes = 0
        self._part_start_ns = None

    def _close_part(self) -> None:
        if self._writer is None:
            return
        self._writer.close()
        self._writer = None
        pdir = self._part_dir(self._part)
        meta = yaml.safe_load((pdir / "metadata.yaml").read_text(encoding="utf-8"))
        info = meta["rosbag2_bagfile_information"]
        src = pdir / str(info["relative_file_paths"][0])
        dst = self.path / f"{pdir.name}.mcap"
        src.replace(dst)
        shutil.rmtree(pdir)
        self._parts.append((dst, info))

    # -- writing -----------------------------------------------------------------------------

    def write(self, topic: str, timestamp_ns: int, data: bytes | memoryview) -> None:
        """Store one raw CDR message of a declared topic."""
        if self.closed:
            raise DataError(self.path, None, "bag already closed")
        if topic not in self._topics:
            raise DataError(self.path, None, f"topic {topic} written before add_topic()")
        if self._writer is not None and self._should_split(timestamp_ns, len(data)):
            self._close_part()
        if self._writer is None:
            self._open_part()
        assert self._writer is not None
        self._writer.write(self._conns[topic], int(timestamp_ns), data)
        self._part_bytes += len(data)
        if self._part_start_ns is None or timestamp_ns < self._part_start_ns:
            self._part_start_ns = int(timestamp_ns)
        self.counts[topic] += 1

    def _should_split(self, stamp: int, size: int) -> bool:
        if self._part_bytes == 0:
            return False
        if self.max_bytes and self._part_bytes + size > self.max_bytes:
            return True
        return bool(
            self.max_duration_ns
            and self._part_start_ns is not None
            and stamp - self._part_start_ns >= self.max_duration_ns
        )

    def flush(self) -> None:
        """Put every message written so far on disk as a complete MCAP chunk, so that a
        process killed later loses nothing written before this call (rosbags otherwise keeps up
        to 1 MiB of messages in memory). A no-op when rosbags' MCAP writer changes shape."""
        storage = getattr(self._writer, "storage", None)
        chunk = getattr(storage, "chunk", None)
        bio = getattr(chunk, "bio", None)
        if storage is None or bio is None or not hasattr(storage, "close_chunk"):
            return
        if bio.tell() and getattr(chunk, "msgs", None):
            storage.close_chunk()
            storage.bio.flush()

    def close(self) -> WrittenBag:
        """Finish the open part and write the bag's ``metadata.yaml``. Idempotent."""
        if self.closed:
            return WrittenBag(self.path, [p for p, _ in self._parts], dict(self.counts))
        if self._writer is None:  # nothing written: still produce a valid (empty) bag
            self._open_part()
        self._close_part()
        self.closed = True
        self._write_metadata()
        return WrittenBag(self.path, [p for p, _ in self._parts], dict(self.counts))

    def abort(self) -> None:
        """Stop without finishing (used only on errors)."""
        if self._writer is not None:
            self._writer.abort()
            self._writer = None
        self.closed = True

    def _write_metadata(self) -> None:
        infos = [info for _, info in self._parts]
        files = []
        starts = []
        ends = []
        for path, info in self._parts:
            start = int(info["starting_time"]["nanoseconds_since_epoch"])
            dur = int(info["duration"]["nanoseconds"])
            count = int(info["message_count"])
            files.append(
                {
                    "path": path.name,
                    "starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": dur},
                    "message_count": count,
                }
            )
            if count:
                starts.append(start)
                ends.append(start + dur)
        first = infos[0]
        topics = []
        for entry in first["topics_with_message_count"]:
            name = entry["topic_metadata"]["name"]
            topics.append(
                {"topic_metadata": entry["topic_metadata"], "message_count": self.counts[name]}
            )
        start = min(starts) if starts else 0
        merged = dict(first)
        merged.update(
            {
                "relative_file_paths": [f["path"] for f in files],
                "files": files,
                "starting_time": {"nanoseconds_since_epoch": start},
                "duration": {"nanoseconds": (max(ends) - start) if ends else 0},
                "message_count": sum(self.counts.values()),
                "topics_with_message_count": topics,
                "ros_distro": "jazzy",
            }
        )
        text = yaml.safe_dump(
            {"rosbag2_bagfile_information": merged}, default_flow_style=False, sort_keys=False
        )
        tmp = self.path / "metadata.yaml.tmp"
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(self.path / "metadata.yaml")


def _to_rosbags_qos(q: dict[str, Any]) -> Any:
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    def enum(cls: Any, value: Any, default: Any) -> Any:
        if isinstance(value, int):
            try:
                return cls(value)
            except ValueError:
                return default
        if isinstance(value, str):
            return getattr(cls, value.upper(), default)
        return default

    zero = QosTime(0, 0)
    return Qos(
        enum(QosHistory, q.get("history"), QosHistory.KEEP_LAST),
        int(q.get("depth", 0)),
        enum(QosReliability, q.get("reliability"), QosReliability.RELIABLE),
        enum(QosDurability, q.get("durability"), QosDurability.VOLATILE),
        zero,
        zero,
        enum(QosLiveliness, q.get("liveliness"), QosLiveliness.AUTOMATIC),
        zero,
        False,
    )
