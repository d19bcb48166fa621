"""A profile file's layout and its ``extends``: every key checked against the schema (an
unknown key, or one in the wrong section, stops with the file and the key named), then the
file merged over the profile it extends.

Merging: the child's mappings merge key by key into the parent's (recursively), a list or a
value replaces the parent's, and an explicit ``null`` sets null. ``name`` is not inherited
(a profile without one is named after its file). ``extends`` takes a profile name (a file
under ``config/profiles/``) or a path (``.yaml`` or with a ``/``), relative to the file that
extends. Chains are allowed; a cycle or a missing parent stops naming the files.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.profiles.schema import BY_PATH, RETIRED, SECTIONS, belongs
from uav_fusion.core.yamlio import read_yaml_file
from uav_fusion.resources import config_path

#: keys a profile does not inherit from the one it extends
NOT_INHERITED = ("name",)


@dataclass(frozen=True)
class Resolved:
    """A profile document with its parents merged in."""

    doc: dict[str, Any]
    origin: dict[str, str]  # key path -> the file that set its value
    files: tuple[Path, ...]  # the file itself (if any), then its parent, ...


def profile_path(path_or_name: str | Path) -> Path:
    """A profile name (``paper``) maps to ``config/profiles/<name>.yaml``; paths stay paths."""
    s = str(path_or_name)
    p = Path(s)
    if p.suffix in (".yaml", ".yml") or p.is_file() or "/" in s:
        return p
    return config_path(f"profiles/{s}.yaml")


def _parent_path(ref: str, child: Path | None) -> Path:
    p = Path(ref)
    if p.suffix in (".yaml", ".yml") or "/" in ref:
        return p if p.is_absolute() or child is None else child.parent / p
    return config_path(f"profiles/{ref}.yaml")


def _is_file(p: Path) -> bool:
    try:
        return p.is_file()
    except (OSError, ValueError):  # a name too long for the file system, a NUL byte
        return False


def unknown_key(path: str, where: str) -> ConfigError:
    """The error for a key path the schema does not have (in ``where``): what to do when it
    has been retired, else where a key of that name belongs, else the section's keys."""
    if path == "association.mode":
        return ConfigError(
            f"{where}: association.mode is no longer a key: the estimator is chosen by the "
            "top-level key 'estimator: paper | tracker | multi' (track_score: tracker)"
        )
    if path in RETIRED:
        return ConfigError(f"{where}: '{path}' is no longer a key: {RETIRED[path]}")
    section, _, name = path.rpartition(".")
    there = [p for p in belongs(name) if p != path]
    if there:
        return ConfigError(
            f"{where}: unknown key '{path}': it belongs at {' or '.join(there)}"
        )
    allowed = [p.rpartition(".")[2] for p in (*BY_PATH, *SECTIONS)
               if p and p.rpartition(".")[0] == section]
    return ConfigError(f"{where}: unknown key '{path}' (allowed: {', '.join(allowed)})")


def check_layout(doc: dict[Any, Any], where: str, section: str = "") -> None:
    """Every key of ``doc`` is a key or a section of the schema, and sections are mappings."""
    for k, v in doc.items():
        path = f"{section}.{k}" if section else str(k)
        if path in BY_PATH:
            continue
        if path not in SECTIONS:
            if isinstance(v, dict):  # a section that has left the schema: name its key
                for sub in v:
                    if f"{path}.{sub}" in RETIRED:
                        raise unknown_key(f"{path}.{sub}", where)
            raise unknown_key(path, where)
        if v is None:
            continue
        if not isinstance(v, dict):
            raise ConfigError(f"{where}: '{path}' must be a mapping, got {type(v).__name__}")
        check_layout(v, where, path)


def _leaves(doc: dict[Any, Any], prefix: str = "") -> list[str]:
    out = []
    for k, v in doc.items():
        path = f"{prefix}.{k}" if prefix else str(k)
        out.extend(_leaves(v, path) if isinstance(v, dict) and path in SECTIONS else [path])
    return out


def merge(parent: dict[Any, Any], child: dict[Any, Any]) -> dict[Any, Any]:
    """``child`` over ``parent``: mappings merge key by key, anything else replaces."""
    out = dict(parent)
    for k, v in child.items():
        old = out.get(k)
        out[k] = merge(old, v) if isinstance(v, dict) and isinstance(old, dict) else v
    return out


def resolve(doc: Any, source: Path | None, seen: tuple[Path, ...] = ()) -> Resolved:
    """``doc`` (the document of ``source``) with the profiles it extends merged under it."""
    where = str(source) if source else "<profile>"
    if not isinstance(doc, dict):
        raise ConfigError(f"{where}: expected a mapping at top level")
    check_layout(doc, where)
    own = {k: v for k, v in doc.items() if k != "extends"}
    origin = dict.fromkeys(_leaves(own), where)
    files = (source,) if source else ()
    ref = doc.get("extends")
    if ref is None:
        return Resolved(own, origin, files)
    if not isinstance(ref, str) or not ref:
        raise ConfigError(f"{where}: extends must be a profile name or a path, got {ref!r}")
    parent = _parent_path(ref, source)
    chain = (*seen, *(p.resolve() for p in files))
    if not _is_file(parent):
        raise ConfigError(f"{where}: extends '{ref}': no profile file {parent}")
    if parent.resolve() in chain:
        names = " -> ".join(str(p) for p in (*chain, parent.resolve()))
        raise ConfigError(f"{where}: extends '{ref}' makes a cycle: {names}")
    base = resolve(read_yaml_file(parent, "profile file"), parent, chain)
    inherited = {k: v for k, v in base.doc.items() if k not in NOT_INHERITED}
    kept = {p: f for p, f in base.origin.items() if p.split(".")[0] not in NOT_INHERITED}
    return Resolved(merge(inherited, own), {**kept, **origin}, files + base.files)
