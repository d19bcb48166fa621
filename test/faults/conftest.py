"""Shared pieces of the fault-injection suite (docs/faults.md is its table of cases).

Every test in ``test/faults`` is one case of the table and carries ``@pytest.mark.fault(ID)``;
``test_fault_table.py`` checks that the table in docs/faults.md and the marked tests agree
one to one, so neither can drift.
"""

from __future__ import annotations

from pathlib import Path

import pytest


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "fault(case_id): the row of docs/faults.md this test implements"
    )


@pytest.fixture(scope="session")
def short_flight(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 30 s synthetic flight in the Dataset-28 formats (read-only: copy before damaging)."""
    from test_graph_flight import write_flight

    return write_flight(tmp_path_factory.mktemp("faults") / "short", seconds=30.0)


