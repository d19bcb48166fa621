"""The pure reorder buffer: any arrival interleaving gives the same release order."""

from __future__ import annotations

import random

import pytest

from uav_fusion.core.live.reorder import Batch, ReorderBuffer

# (source, t, label): radar frames at 0.25 s (two candidates at t = 1.0), RF at ~3.9 s
STREAMS = {
    "radar": [("radar", 0.25 * k, f"r{k}") for k in range(1, 40)]
    + [("radar", 1.0, "r4b")],
    "rf": [("rf", 3.88 * k + 0.1, f"f{k}") for k in range(3)] + [("rf", 2.0, "f_tie")],
}


def _sorted_streams() -> dict[str, list[tuple[str, float, str]]]:
    return {k: sorted(v, key=lambda e: e[1]) for k, v in STREAMS.items()}


def _expected() -> list[tuple[float, str, list[str]]]:
    buf: ReorderBuffer[str] = ReorderBuffer(1e9, ["radar", "rf"], grouped=["radar"])
    for stream in _sorted_streams().values():
        for src, t, lab in stream:
            buf.push(src, t, lab)
    return [(b.t, b.source, b.items) for b in buf.flush()]


def _interleave(seed: int, max_delay: float) -> list[tuple[str, float, str]]:
    """A random merge of the FIFO streams: each item is delayed by up to ``max_delay``
    seconds, and each stream keeps its own order."""
    rng = random.Random(seed)
    arrivals: list[tuple[float, int, tuple[str, float, str]]] = []
    for stream in _sorted_streams().values():
        last = -1.0
        for e in stream:
            last = max(last, e[1] + rng.uniform(0.0, max_delay))
            arrivals.append((last, len(arrivals), e))
    return [e for _, _, e in sorted(arrivals)]


def test_expected_order_groups_frames_and_breaks_ties_by_source_rank() -> None:
    exp = _expected()
    times = [t for t, _, _ in exp]
    assert times == sorted(times)
    frame = [items for t, s, items in exp if s == "radar" and t == 1.0]
    assert frame == [["r4", "r4b"]]
    at2 = [(s, items) for t, s, items in exp if t == 2.0]
    assert at2 == [("radar", ["r8"]), ("rf", ["f_tie"])]


@pytest.mark.parametrize("seed", range(30))
def test_any_fifo_interleaving_releases_the_same_sequence(seed: int) -> None:
    buf: ReorderBuffer[str] = ReorderBuffer(4.0, ["radar", "rf"], grouped=["radar"])
    got: list[Batch[str]] = []
    for src, t, lab in _interleave(seed, 3.99):
        assert buf.push(src, t, lab)
        got.extend(buf.release())
    got.extend(buf.flush())
    assert [(b.t, b.source, b.items) for b in got] == _expected()
    assert sum(buf.late.values()) == 0


def test_delays_beyond_the_window_make_late_items() -> None:
    late = 0
    for seed in range(10):
        buf: ReorderBuffer[str] = ReorderBuffer(0.5, ["radar", "rf"], grouped=["radar"])
        for src, t, lab in _interleave(seed, 6.0):
            buf.push(src, t, lab)
            buf.release()
        late += sum(buf.late.values())
    assert late > 0


def test_release_waits_for_the_slowest_stream_then_for_the_window() -> None:
    buf: ReorderBuffer[str] = ReorderBuffer(2.0, ["radar", "rf"], grouped=["radar"])
    buf.push("radar", 10.0, "a")
    assert buf.release() == []  # rf never seen, watermark 10 < 10 + 2
    buf.push("radar", 11.0, "b")
    assert buf.release() == []
    buf.push("radar", 12.0, "c")
    assert [b.items for b in buf.release()] == [["a"]]  # 10 <= 12 - 2
    buf.note("rf", 11.5)  # failed RF attempt: progress without an item
    assert [b.items for b in buf.release()] == [["b"]]  # 11 < min(12, 11.5)
    assert buf.pending == 1
    assert [b.items for b in buf.release(clock=20.0)] == [["c"]]  # the sim clock moved on


def test_late_items_are_refused_and_counted() -> None:
    buf: ReorderBuffer[str] = ReorderBuffer(1.0, ["radar", "rf"], grouped=["radar"])
    buf.push("radar", 5.0, "a")
    buf.push("radar", 7.0, "b")
    assert [b.items for b in buf.release()] == [["a"]]
    assert not buf.push("rf", 4.0, "old")
    assert not buf.push("radar", 5.0, "same frame, after its release")
    assert buf.push("rf", 5.0, "tie after radar is still in order")
    assert buf.late == {"rf": 1, "radar": 1}


def test_bad_arguments() -> None:
    with pytest.raises(ValueError):
        ReorderBuffer(-1.0, ["a"])
    with pytest.raises(ValueError):
        ReorderBuffer(1.0, [])
    buf: ReorderBuffer[int] = ReorderBuffer(1.0, ["a"])
    with pytest.raises(ValueError):
        buf.push("b", 1.0, 1)
    with pytest.raises(ValueError):
        buf.push("a", float("nan"), 1)
