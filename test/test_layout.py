"""The package's shape: no module over 600 lines (the size rule of the architecture; ruff's
PLR0915 in `make lint` keeps every function under 80 statements)."""

from __future__ import annotations

from pathlib import Path

import uav_fusion

MAX_LINES = 600


def test_no_module_is_over_600_lines() -> None:
    root = Path(uav_fusion.__file__).parent
    sizes = {p: len(p.read_text(encoding="utf-8").splitlines()) for p in root.rglob("*.py")}
    assert len(sizes) > 100
    over = {str(p.relative_to(root)): n for p, n in sizes.items() if n > MAX_LINES}
    assert not over, f"modules over {MAX_LINES} lines: {over}"
