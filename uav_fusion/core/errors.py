"""Error types shared by the core."""

from __future__ import annotations

from pathlib import Path


class UavFusionError(Exception):
    """Base class of every error the package raises on purpose."""


class ConfigError(UavFusionError):
    """A configuration file or parameter is missing or wrong."""


class DataError(UavFusionError):
    """Input data is unreadable or wrong; names the file and line when known."""

    def __init__(self, path: str | Path | None, line: int | None, what: str) -> None:
        self.path = None if path is None else Path(path)
        self.line = line
        self.what = what
        where = "" if path is None else str(path)
        if line is not None:
            where += f":{line}"
        super().__init__(f"{where}: {what}" if where else what)
