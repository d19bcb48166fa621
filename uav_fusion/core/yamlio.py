"""Reading YAML configuration files with errors that name the file."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from .errors import ConfigError


def read_yaml_file(path: Path, what: str) -> Any:
    """Parse the YAML document in ``path``; ``what`` names the file kind in errors.

    Raises ConfigError ``"<path>: <what> not found"`` when ``path`` is not a file and
    ``"<path>: not valid YAML: <reason>"`` when it is not UTF-8 or not YAML. The parsed
    document is returned as it is (an empty file gives None); checking its shape is the
    caller's part, as the ``*_from_dict`` builders also accept documents made in code.
    """
    if not path.is_file():
        raise ConfigError(f"{path}: {what} not found")
    try:
        return yaml.safe_load(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError, ValueError) as exc:
        # ValueError: PyYAML's int() of an integer longer than Python's 4300-digit limit
        raise ConfigError(f"{path}: not valid YAML: {exc}") from None
