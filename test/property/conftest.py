"""Property tests: Hypothesis profiles are registered and chosen in propkit (``ci`` by
default; ``fuzz`` with ``UAV_FUZZ=1``, as ``make fuzz`` does)."""

from __future__ import annotations

import propkit  # noqa: F401  (registers and loads the settings profile)
