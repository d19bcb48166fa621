"""File-writing and strict-mode helpers shared by the dataset reader tests."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from uav_fusion.core.errors import DataError
from uav_fusion.core.site import Site


def lines(*rows: str) -> str:
    """Rows joined into file text, each ended by a newline."""
    return "\n".join(rows) + "\n"


class ReaderFiles:
    """Writes test files under a reader's usual file name and runs the reader strictly."""

    def __init__(self, reader: Callable[..., Any], default_name: str) -> None:
        self.reader = reader
        self.default_name = default_name

    def write(self, tmp_path: Path, content: str | bytes, name: str | None = None) -> Path:
        """``content`` (text as UTF-8, or raw bytes) in ``tmp_path / name``."""
        p = tmp_path / (name or self.default_name)
        if isinstance(content, str):
            p.write_text(content, encoding="utf-8")
        else:
            p.write_bytes(content)
        return p

    def strict_error(self, p: Path, site: Site) -> DataError:
        """The DataError the reader raises on ``p`` in strict mode (fails if none)."""
        with pytest.raises(DataError) as ei:
            self.reader(p, site, strict=True)
        return ei.value
