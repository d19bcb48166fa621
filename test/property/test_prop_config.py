"""Mutated configuration files load or raise the project's ConfigError naming file and key.

Each example starts from a shipped YAML file (site, estimator profile, twin configuration,
waypoints), changes one or more places in the parsed document (a value replaced by a value of
any YAML type: null, bool, huge or negative numbers, NaN / inf, strings, lists, mappings; a
key deleted; an unknown key added) or damages the file's bytes, and loads it with the public
loader. Allowed outcomes: a loaded configuration, or ``ConfigError`` whose message names the
file (and, for a document change, one of the changed keys or a section above it).
"""

from __future__ import annotations

import copy
import math
import re
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml
from hypothesis import given
from hypothesis import strategies as st
from propkit import damaged_lines, examples

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.profiles.model import load_profile
from uav_fusion.core.site import load_site
from uav_fusion.core.twin.config import load_twin_config
from uav_fusion.core.twin.trajectory import load_flight_plan

CONFIG = Path(__file__).resolve().parents[2] / "config"
SITE = load_site()

LOADERS: dict[str, tuple[Path, Callable[[Path], Any]]] = {
    "site": (CONFIG / "site_lake_wheeler.yaml", load_site),
    "profile": (CONFIG / "profiles" / "paper.yaml", load_profile),
    "tracker": (CONFIG / "profiles" / "tracker.yaml", load_profile),
    "tracker_smoothed": (CONFIG / "profiles" / "tracker_smoothed.yaml", load_profile),
    "twin": (CONFIG / "twin_default.yaml", load_twin_config),
    "waypoints": (
        CONFIG / "waypoints" / "lake_wheeler_default.yaml",
        lambda p: load_flight_plan(p, SITE),
    ),
}
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
DOCS = {k: yaml.safe_load(p.read_text()) for k, (p, _) in LOADERS.items()}

yaml_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),
    st.sampled_from([10**400, -(10**400), 2**63, -1, 0]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=10),
    st.sampled_from(["", "cv", "radar", "rf", "LW1", "nan", "1e400", "-999", "x" * 300]),
)
yaml_values = st.recursive(
    yaml_scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=3)
    ),
    max_leaves=6,
)


def _paths(doc: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every place in the document (keys of mappings, indexes of lists)."""
    out: list[tuple[Any, ...]] = []
    if isinstance(doc, dict):
        for k, v in doc.items():
            out.append((*prefix, k))
            out.extend(_paths(v, (*prefix, k)))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out.append((*prefix, i))
            out.extend(_paths(v, (*prefix, i)))
    return out


PATHS = {k: _paths(d) for k, d in DOCS.items()}


@st.composite
def mutated(draw: st.DrawFn, kind: str) -> tuple[Any, list[tuple[Any, ...]]]:
    doc = copy.deepcopy(DOCS[kind])
    changed: list[tuple[Any, ...]] = []
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(PATHS[kind]))
        parent: Any = doc
        try:
            for k in path[:-1]:
                parent = parent[k]
            last = path[-1]
            parent[last]  # the place still exists after earlier changes
        except (KeyError, IndexError, TypeError):
            continue
        op = draw(st.sampled_from(("replace", "replace", "delete", "add")))
        if op == "replace":
            parent[last] = draw(yaml_values)
        elif op == "delete":
            del parent[last]
        elif isinstance(parent, dict):
            key = draw(st.text(min_size=1, max_size=8))
            parent[key] = draw(yaml_values)
            path = (*path[:-1], key)
        else:
            parent.append(draw(yaml_values))
            path = (*path[:-1], len(parent) - 1)
        changed.append(path)
    return doc, changed


def _names(path: tuple[Any, ...]) -> set[str]:
    """The key names along a path (the changed key and the sections above it), and for a
    list item its 1-based number (give or take 3: earlier deletions shift the items)."""
    names = {str(k) for k in path if isinstance(k, str)}
    names |= {n[:-1] for n in names if n.endswith("s")}  # 'waypoints' -> 'waypoint 3'
    for k in path:
        if isinstance(k, int):
            names |= {str(j + 1) for j in range(max(k - 3, 0), k + 4)}
    return names


def _names_any(msg: str, names: set[str]) -> bool:
    return any(re.search(rf"(?<!\w){re.escape(n)}(?!\w)", msg) for n in names)


def _load(kind: str, text: bytes) -> tuple[Path, Any, ConfigError | None]:
    path, loader = LOADERS[kind]
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / path.name
        p.write_bytes(text)
        try:
            return p, loader(p), None
        except ConfigError as exc:
            return p, None, exc


def _check_document(kind: str, doc: Any, changed: list[tuple[Any, ...]]) -> None:
    text = yaml.dump(doc, Dumper=_DUMPER, allow_unicode=True).encode()
    p, cfg, err = _load(kind, text)
    if err is None:
        assert cfg is not None
        return
    msg = str(err)
    assert msg.startswith(f"{p}: "), msg
    named = set().union(*(_names(c) for c in changed)) if changed else set()
    assert not changed or _names_any(msg, named), f"{msg!r} names none of {named}"


@examples(ci=100)
@given(
    kind=st.sampled_from(sorted(LOADERS)),
    damage=st.sampled_from(("document", "bytes")),
    data=st.data(),
)
def test_changed_config_loads_or_names_file_and_key(
    kind: str, damage: str, data: st.DataObject
) -> None:
    if damage == "document":
        doc, changed = data.draw(mutated(kind))
        _check_document(kind, doc, changed)
        return
    lines = LOADERS[kind][0].read_bytes().split(b"\n")
    blob = data.draw(damaged_lines(lines, sep=b":"))
    p, cfg, err = _load(kind, blob)
    if err is not None:
        assert str(err).startswith(f"{p}"), str(err)
    else:
        assert cfg is not None


def test_shipped_configs_load() -> None:
    for kind, (path, loader) in LOADERS.items():
        assert loader(path) is not None, kind
    assert math.isfinite(SITE.h0)
