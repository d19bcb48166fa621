"""What the single-UAV tracker follows (``uav_fusion analyse locks``).

For every flight of a single-UAV definition's split, each profile's tracker runs over the
flight as ``uav_fusion run`` runs it. After every radar frame with a confirmed track, the
radar object the track follows (the one whose report updated it last) is looked up in the
twin (:mod:`~uav_fusion.core.analysis.labels`), which knows the kind of object every radar
track was following then (UAV, ghost, bird, clutter, vehicle). The time to the next frame is
counted against that kind, and separately when the track is then more than 100 m from the UAV
(a lock: following a ghost mirrored below the UAV mostly costs height only).

Printed: per flight, the seconds on objects other than the UAV (only flights with any), then
per profile the pooled seconds by kind and the locked seconds.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from uav_fusion.core.analysis.labels import (
    FlightSet,
    KindsByTrack,
    LabelledFlight,
    Progress,
    kind_at,
    labelled_flights,
)
from uav_fusion.core.estimators.base import feed
from uav_fusion.core.estimators.selection import frames_input
from uav_fusion.core.estimators.tracker import Tracker
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.records import Flight, RadarFrame
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]
LOCK_M = 100.0


@dataclass(frozen=True)
class FrameFollow:
    """After one radar frame: what the confirmed track follows (``x`` None: no confirmed
    track)."""

    t: float
    followed: int | None  # the radar track id of its last radar update
    x: FloatArray | None  # its state predicted to ``t``


@dataclass(frozen=True)
class ProfileLocks:
    seconds: dict[str, float]  # seconds of confirmed track by the kind of object it follows
    locked_s: float  # ... on another object, with the track more than LOCK_M off the UAV


@dataclass(frozen=True)
class FlightLocks:
    tag: str
    profiles: dict[str, ProfileLocks]

    def line(self) -> str:
        parts = []
        for name, pl in self.profiles.items():
            other = {c: s for c, s in pl.seconds.items() if c != "uav"}
            if other:
                what = ", ".join(f"{c} {s:.1f}" for c, s in sorted(other.items()))
                parts.append(f"{name}: {what} s; more than {LOCK_M:.0f} m off {pl.locked_s:.1f} s")
        return f"{self.tag}: " + ("; ".join(parts) or "the UAV only")


def _follow(flight: Flight, profile: Profile, site: Site) -> Iterator[FrameFollow]:
    """The estimator's part: the single-UAV tracker over the flight, and after every radar
    frame what its confirmed track follows."""
    tracker = Tracker(profile, site)
    for item in frames_input(flight, profile):
        feed(tracker, item)
        if not isinstance(item, RadarFrame):
            continue
        if tracker.confirmed and tracker.filter is not None:
            x, _ = tracker.predict_to(item.t)
            yield FrameFollow(item.t, tracker.followed, x)
        else:
            yield FrameFollow(item.t, None, None)


def profile_locks(
    frames: Iterator[FrameFollow], kinds: KindsByTrack, tt: FloatArray, enu: FloatArray
) -> ProfileLocks:
    """Seconds by the kind followed, from frame to frame, and the locked seconds (module
    text)."""
    secs: dict[str, float] = {}
    lock = 0.0
    prev: tuple[float, str, bool] | None = None  # (t, kind, more than LOCK_M off)
    for fr in frames:
        t = fr.t
        if prev is not None:
            secs[prev[1]] = secs.get(prev[1], 0.0) + (t - prev[0])
            if prev[2]:
                lock += t - prev[0]
        prev = None
        if fr.x is None:
            continue
        ka = kind_at(kinds, fr.followed, t)
        kind = ka[0] if ka is not None else "RF fixes only"
        off = False
        if kind != "uav":
            p = np.array([np.interp(t, tt, enu[:, i]) for i in range(3)])
            off = float(np.linalg.norm(fr.x[:3] - p)) > LOCK_M
        prev = (t, kind, off)
    return ProfileLocks(secs, lock)


def _flight(lf: LabelledFlight, profiles: Sequence[Profile], site: Site) -> FlightLocks:
    tt, enu = lf.flight.truth_arrays()
    out = {p.name: profile_locks(_follow(lf.flight, p, site), lf.kinds, tt, enu) for p in profiles}
    return FlightLocks(lf.tag, out)


def locks(
    fs: FlightSet, profiles: Sequence[Profile], progress: Progress | None = None
) -> Iterator[FlightLocks]:
    """What each profile's tracker follows, flight by flight."""
    for lf in labelled_flights(fs, progress):
        yield _flight(lf, profiles, fs.site)


def summary(flights: Sequence[FlightLocks], names: Sequence[str]) -> list[str]:
    """Per profile: the pooled seconds by kind and the locked seconds."""
    out = ["", f"pooled over {len(flights)} flights (seconds of confirmed track by what it "
               "follows):"]  # fmt: skip
    for name in names:
        c: dict[str, float] = {}
        locked = 0.0
        for f in flights:
            for kind, s in f.profiles[name].seconds.items():
                c[kind] = s + c.get(kind, 0)
            locked += f.profiles[name].locked_s
        total = sum(c.values())
        # largest first, ties in the order first seen
        ranked = sorted(c.items(), key=lambda kv: kv[1], reverse=True)
        row = ", ".join(f"{kind} {s:.1f}" for kind, s in ranked)
        out.append(
            f"  {name}: {row} (of {total:.1f} s); more than {LOCK_M:.0f} m off the UAV "
            f"while on another object: {locked:.1f} s"
        )
    return out
