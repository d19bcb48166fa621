"""Put a ``uav_fusion bench`` run's tables into README.md (between the bench markers).

    python scripts/update_bench_readme.py out/bench/accuracy-test [--readme README.md]

Reads ``table.md`` and ``summary.json`` of the bench output folder and replaces the block
between ``<!-- bench-accuracy:begin -->`` and ``<!-- bench-accuracy:end -->`` with the run's
command line, date, commit, wall time and both tables. Text outside the block (the discussion
of the figures) is not touched: re-read it against the new tables.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

BEGIN = "<!-- bench-accuracy:begin -->"
END = "<!-- bench-accuracy:end -->"


def block(folder: Path) -> str:
    summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    prov = summary["provenance"]
    profiles = " ".join(summary["pooled"])
    versions = ", ".join(f"{k} {v}" for k, v in prov["versions"].items())
    lines = [
        BEGIN,
        f"Measured {prov['date']} with `uav_fusion bench --profiles {profiles}` "
        f"({prov['split']} half, {prov['flights']} flights; commit `{prov['commit']}`; "
        f"{versions}). Wall time {prov.get('wall_time', 'not recorded')}.",
        "",
        (folder / "table.md").read_text(encoding="utf-8").rstrip(),
        END,
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help="the bench output folder (--out)")
    ap.add_argument("--readme", type=Path, default=Path("README.md"))
    args = ap.parse_args(argv)
    text = args.readme.read_text(encoding="utf-8")
    if BEGIN not in text or END not in text:
        print(f"{args.readme}: the markers {BEGIN} / {END} are missing", file=sys.stderr)
        return 2
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    args.readme.write_text(head + block(args.folder) + tail, encoding="utf-8")
    print(f"{args.readme}: bench block replaced from {args.folder}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
