"""``uav_fusion emulate FOLDER``: write a flight folder out as the sensors would, line by line,
at real time or faster (:mod:`uav_fusion.core.ingest.emulator`).

By default each source is a TCP server on 127.0.0.1 (radar 5601, RF 5602, truth 5603), the
addresses the stream nodes connect to by default; ``--out DIR`` writes files instead (the
folder's own file names), and ``--radar/--rf/--truth URL`` choose per source
(``tcp://HOST:PORT`` listens, ``udp://HOST:PORT`` sends datagrams there, ``file:PATH``
writes). ``--delay rf=3 --jitter rf=1`` makes RF arrive 3 s ± 1 s late (seeded by ``--seed``);
``--schedule FILE`` writes the arrival schedule (CSV, see the module above).
"""

from __future__ import annotations

import argparse
import signal
import threading
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING

from uav_fusion.core.errors import ConfigError

if TYPE_CHECKING:
    from uav_fusion.core.ingest.emulator import Emulator

HELP = "write a flight folder out as the sensors would (files, TCP or UDP), in real time"

DEFAULT_URLS = {
    "radar": "tcp://127.0.0.1:5601",
    "rf": "tcp://127.0.0.1:5602",
    "truth": "tcp://127.0.0.1:5603",
}


def per_source(values: list[str] | None, what: str) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in values or []:
        src, eq, num = item.partition("=")
        if not eq or src not in DEFAULT_URLS:
            raise ConfigError(f"--{what} {item!r}: write SOURCE=SECONDS, SOURCE one of "
                              f"{', '.join(DEFAULT_URLS)}")
        try:
            out[src] = float(num)
        except ValueError:
            raise ConfigError(f"--{what} {item!r}: {num!r} is not a number") from None
        if not out[src] >= 0:
            raise ConfigError(f"--{what} {item!r}: must be >= 0")
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", type=Path, help="flight folder in the Dataset-28 layout")
    parser.add_argument("--rate", type=float, default=1.0,
                        help="speed: 1 = real time (default), 10 = ten times, 0 = as fast as "
                        "the outputs take the lines")
    parser.add_argument("--out", type=Path, metavar="DIR",
                        help="write files into DIR (created) under the folder's file names")
    for src in DEFAULT_URLS:
        parser.add_argument(f"--{src}", metavar="URL",
                            help=f"output of the {src} lines (default {DEFAULT_URLS[src]}, "
                            "or a file in --out)")
    parser.add_argument("--sources", default="radar,rf,truth",
                        help="sources to emulate, comma-separated (default radar,rf,truth)")
    parser.add_argument("--delay", action="append", metavar="SOURCE=S",
                        help="send SOURCE's lines S sensor seconds late (repeatable)")
    parser.add_argument("--jitter", action="append", metavar="SOURCE=S",
                        help="add a uniform jitter of +-S seconds to SOURCE's delay")
    parser.add_argument("--seed", type=int, default=0, help="seed of the jitter (default 0)")
    parser.add_argument("--start", type=float, default=0.0, metavar="S",
                        help="begin S sensor seconds into the flight")
    parser.add_argument("--duration", type=float, default=None, metavar="S",
                        help="send only S sensor seconds of the flight")
    parser.add_argument("--schedule", type=Path, metavar="CSV",
                        help="write the arrival schedule: source,line,sensor_t,due_t,"
                        "sent_unix,sent_mono")
    parser.add_argument("--wait", type=float, default=30.0, metavar="S",
                        help="wait up to S seconds for TCP clients before starting (30)")
    parser.add_argument("--overwrite", action="store_true", help="replace existing files")
    parser.add_argument("--rf-file", default="AADM.csv", help="RF CSV name (default AADM.csv)")
    parser.add_argument("--site", type=Path, default=None, help="site YAML (default: bundled)")


def build(args: argparse.Namespace) -> tuple[Emulator, dict[str, int]]:
    """The emulator of ``args`` (sinks open) and the planned line count per source."""
    from uav_fusion.core.data.flight import flight_files
    from uav_fusion.core.ingest.emulator import Emulator, open_sink, plan, read_sensor_lines
    from uav_fusion.core.site import load_site

    if args.rate < 0:
        raise ConfigError(f"--rate must be >= 0, got {args.rate}")
    sources = [s.strip() for s in str(args.sources).split(",") if s.strip()]
    bad = [s for s in sources if s not in DEFAULT_URLS]
    if bad or not sources:
        raise ConfigError(f"--sources: {', '.join(bad) or 'none'}; choose from radar,rf,truth")
    site = load_site(args.site)
    files = flight_files(args.folder, rf_file=args.rf_file)
    lines = {s: read_sensor_lines(files[s], s, site) for s in sources}
    sends = plan(lines, delay_s=per_source(args.delay, "delay"),
                 jitter_s=per_source(args.jitter, "jitter"), seed=args.seed,
                 start_s=args.start, duration_s=args.duration)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
    sinks = {}
    try:
        for s in sources:
            url = getattr(args, s)
            if url is None:
                url = f"file:{args.out / files[s].name}" if args.out else DEFAULT_URLS[s]
            sinks[s] = open_sink(url, overwrite=args.overwrite, what=f"--{s}")
    except BaseException:
        for sink in sinks.values():
            sink.close()
        raise
    counts = {s: sum(1 for x in sends if x.source == s) for s in sources}
    return Emulator(sends, sinks, rate=args.rate, wait_s=args.wait,
                    log=lambda t: print(f"emulate: {t}", flush=True)), counts


def run(args: argparse.Namespace) -> int:
    from uav_fusion.core.ingest.emulator import write_schedule

    emu, counts = build(args)
    stop = threading.Event()

    def on_signal(_sig: int, _frame: FrameType | None) -> None:
        stop.set()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        outs = ", ".join(f"{s} -> {sink.name}" for s, sink in emu.sinks.items())
        span = (emu.sends[-1].due - emu.sends[0].due) if emu.sends else 0.0
        pace = "as fast as possible" if args.rate == 0 else f"at {args.rate:g}x"
        print(f"emulate: {args.folder}: {sum(counts.values())} lines ({counts}) over "
              f"{span:.1f} sensor s {pace}: {outs}", flush=True)
        res = emu.run(stop)
    finally:
        emu.close()
        for s, h in old.items():
            signal.signal(s, h)
    if args.schedule is not None:
        write_schedule(args.schedule, emu.rows)
        print(f"emulate: arrival schedule written to {args.schedule}")
    print(f"emulate: sent {res.sent} in {res.wall_s:.1f} s wall; lateness against the plan "
          f"p50 {res.lag_p50_s * 1e3:.2f} ms, max {res.lag_max_s * 1e3:.1f} ms"
          + (" (stopped)" if res.stopped else ""))
    return 0
