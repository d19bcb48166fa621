"""Locate the package's shipped files (config/, bench/, data/, bags/) in a source tree or an
install."""

from __future__ import annotations

import sys
from pathlib import Path

PACKAGE = "uav_fusion"


def share_dir() -> Path:
    """Directory holding config/, bench/, data/ and bags/.

    In a source checkout (or an editable install) that is the repository root; in a colcon or
    pip install it is ``<prefix>/share/uav_fusion``.
    """
    repo_root = Path(__file__).resolve().parent.parent
    if (repo_root / "config").is_dir() and (repo_root / "package.xml").is_file():
        return repo_root
    for prefix in {Path(sys.prefix), Path(__file__).resolve().parents[4]}:
        cand = prefix / "share" / PACKAGE
        if (cand / "config").is_dir():
            return cand
    try:  # an ament install with several prefixes
        from ament_index_python.packages import get_package_share_directory  # type: ignore

        return Path(get_package_share_directory(PACKAGE))
    except Exception:
        pass
    return repo_root


def config_path(name: str) -> Path:
    """Path of a file under config/."""
    return share_dir() / "config" / name


def bench_path(name: str) -> Path:
    """Path of a file under bench/ (benchmark definitions)."""
    return share_dir() / "bench" / name


def data_path(name: str) -> Path:
    """Path of a file or folder under data/."""
    return share_dir() / "data" / name


DEFAULT_SITE = "site_lake_wheeler.yaml"
DEFAULT_FLIGHT = "default_flight"
