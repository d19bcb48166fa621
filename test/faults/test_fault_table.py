"""The table in docs/faults.md and the fault tests agree one to one (neither can drift).

Each table row names a case id and a test (``file::function``). A row whose test lives in
``test/faults`` must name the function that carries ``@pytest.mark.fault(<id>)``; a row may
also point to a test elsewhere in ``test/`` (a fault already covered by another module's
tests), which must exist. Every marked test in ``test/faults`` must have its row.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

TEST_DIR = Path(__file__).resolve().parent
ROOT = TEST_DIR.parents[1]
DOC = ROOT / "docs" / "faults.md"
ROW = re.compile(r"^\|\s*([A-Z]+-\d{2})\s*\|(.*)\|\s*$")
TEST_REF = re.compile(r"`(test/[\w/]+\.py)::(test_\w+)`")


def table_rows() -> dict[str, tuple[str, str, list[str]]]:
    """case id -> (test file, test function, the other cells)."""
    rows: dict[str, tuple[str, str, list[str]]] = {}
    for line in DOC.read_text().splitlines():
        m = ROW.match(line.strip())
        if not m:
            continue
        cid, rest = m.group(1), m.group(2)
        cells = [c.strip() for c in rest.split("|")]
        ref = TEST_REF.search(rest)
        assert ref, f"row {cid} names no test as `test/<file>.py::test_<name>`"
        assert cid not in rows, f"case {cid} appears twice in docs/faults.md"
        rows[cid] = (ref.group(1), ref.group(2), cells)
    return rows


def _mark_id(dec: ast.expr) -> str | None:
    if (
        isinstance(dec, ast.Call)
        and isinstance(dec.func, ast.Attribute)
        and dec.func.attr == "fault"
        and dec.args
        and isinstance(dec.args[0], ast.Constant)
    ):
        return str(dec.args[0].value)
    return None


def functions(path: Path) -> dict[str, list[str]]:
    """Test function name -> the fault ids it is marked with."""
    tree = ast.parse(path.read_text())
    out: dict[str, list[str]] = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name.startswith("test_"):
            out[node.name] = [i for d in node.decorator_list if (i := _mark_id(d))]
    return out


def marked_cases() -> dict[str, tuple[str, str]]:
    cases: dict[str, tuple[str, str]] = {}
    for path in sorted(TEST_DIR.glob("test_fault_*.py")):
        for name, ids in functions(path).items():
            for cid in ids:
                assert cid not in cases, f"{cid} marks two tests: {cases[cid]} and {name}"
                cases[cid] = (f"test/faults/{path.name}", name)
    return cases


def test_table_and_marked_tests_agree() -> None:
    rows = table_rows()
    marked = marked_cases()
    in_suite = {cid for cid, (f, _, _) in rows.items() if f.startswith("test/faults/")}
    assert in_suite == set(marked), (
        f"only in the table: {sorted(in_suite - set(marked))}; "
        f"only in the tests: {sorted(set(marked) - in_suite)}"
    )
    for cid, (f, fn, cells) in rows.items():
        assert len(cells) >= 4 and all(cells[:3]), f"row {cid}: area, fault, expected outcome"
        if cid in marked:
            where = marked[cid]
            assert where == (f, fn), f"row {cid} names {f}::{fn}, the mark is on {where}"
        else:  # a fault covered by another module's tests
            path = ROOT / f
            assert path.is_file(), f"row {cid}: {f} does not exist"
            assert fn in functions(path), f"row {cid}: {f} has no {fn}"


def test_the_suite_has_at_least_forty_cases() -> None:
    rows = table_rows()
    assert len(rows) >= 40
    areas = {cid.split("-")[0] for cid in rows}
    assert areas == {"FILE", "MSG", "TIME", "PROC", "LIVE", "LOAD", "ACC", "FUZZ"}
