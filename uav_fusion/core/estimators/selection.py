"""Which radar reports go where, and the paper estimator's measurement stream.

A flight's radar file gives three streams (``docs/graph.md``):

- the **selected** reports: the radar frames (lists of candidates sharing one stamp) the
  profile's track selection keeps, exactly the radar measurements the paper's estimator is
  fed (:func:`flight_measurements`); with the paper's policy (``largest_track``) that is the
  largest continuous track, chosen with knowledge of the whole flight like the paper did;
- the **raw** reports: every report of the tracks classed as the UAV's by the profile's
  ``evaluation.raw_radar_min_mean_uav_prob`` (:mod:`uav_fusion.core.data.uav_class`), before
  selection: the evaluator's "radar raw" row;
- every report of every frame, unselected: ``radar/tracks`` (:mod:`uav_fusion.core.data.clouds`),
  each report with the covariance of :func:`report_covariance`.

Users: ``radar_replay`` (``radar/pose``, ``radar/raw``, ``radar/tracks``), the bag converter
(the same three topics), ``uav_fusion evaluate`` and ``uav_fusion calibrate``.

Order of the stream is total and deterministic: time, then source (radar before RF at equal
times), then position in the source file. ``seq`` numbers the measurements 0, 1, 2, ... in
that order, so a consumer that processes by (t, seq) reproduces the offline run exactly.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from uav_fusion.core.data.uav_class import uav_class_tracks
from uav_fusion.core.estimators.kalman import PackedR
from uav_fusion.core.profiles.model import Profile, load_profile
from uav_fusion.core.records import (
    RADAR,
    RF,
    Flight,
    Measurement,
    RadarFrame,
    RadarTrack,
    RfAttempt,
)
from uav_fusion.core.site import Site

StreamItem = Measurement | list[Measurement]
FloatArray = npt.NDArray[np.float64]

SOURCE_RANK = {RADAR: 0, RF: 1}


def largest_track_id(frames: Iterable[RadarFrame]) -> int | None:
    """Id of the radar track with the most reports (ties: the lowest id); None if no reports.

    This is the paper's offline "largest continuous track": a track id is continuous by
    construction of the radar's tracker, and "largest" counts reports.
    """
    counts: Counter[int] = Counter(trk.track_id for fr in frames for trk in fr.tracks)
    if not counts:
        return None
    return min(counts, key=lambda k: (-counts[k], k))


@dataclass(frozen=True)
class StreamInfo:
    """What building the stream did: totals and the radar selection."""

    radar_frames: int
    radar_reports: int
    radar_selected: int
    not_selected: int
    selected_track_id: int | None
    rf_attempts: int
    rf_fixes: int


def _radar_measurement(trk: RadarTrack, seq: int) -> Measurement:
    return Measurement(
        t=trk.t,
        source=RADAR,
        z=np.array((trk.e, trk.n, trk.u), dtype=float),
        track_id=trk.track_id,
        uav_prob=trk.uav_prob,
        range_m=trk.range_m,
        seq=seq,
    )


def selected_input(
    flight: Flight, profile: Profile
) -> tuple[list[RadarFrame | RfAttempt], StreamInfo]:
    """What the paper's estimator reads from a flight, in processing order: the radar frames
    cut to the selected reports (frames without one left out) and the RF attempts with a
    finite position; plus a summary of what was selected."""
    keyed: list[tuple[float, int, int]] = []
    if profile.use_radar:
        keyed.extend((fr.t, SOURCE_RANK[RADAR], i) for i, fr in enumerate(flight.radar))
    rf_fixes = 0
    if profile.use_rf:
        for i, a in enumerate(flight.rf):
            if a.ok and np.isfinite(a.e) and np.isfinite(a.n):
                rf_fixes += 1
                keyed.append((a.t, SOURCE_RANK[RF], i))
    keyed.sort()
    largest = profile.radar_selection == "largest_track"
    sel = largest_track_id(flight.radar) if largest and profile.use_radar else None
    out: list[RadarFrame | RfAttempt] = []
    reports = selected = 0
    for _, rank, i in keyed:
        if rank == SOURCE_RANK[RADAR]:
            frame = flight.radar[i]
            reports += len(frame.tracks)
            kept = frame.tracks
            if largest:
                kept = tuple(trk for trk in kept if trk.track_id == sel)
            if kept:
                selected += len(kept)
                out.append(frame if kept is frame.tracks else RadarFrame(frame.t, kept, frame.line))
        else:
            out.append(flight.rf[i])
    info = StreamInfo(
        radar_frames=len(flight.radar) if profile.use_radar else 0,
        radar_reports=reports,
        radar_selected=selected,
        not_selected=reports - selected,
        selected_track_id=sel,
        rf_attempts=len(flight.rf) if profile.use_rf else 0,
        rf_fixes=rf_fixes,
    )
    return out, info


def frames_input(flight: Flight, profile: Profile) -> list[RadarFrame | RfAttempt]:
    """What the trackers read from a flight: every radar frame with a report and every RF
    attempt with a position (``ok``), in (time, radar before RF, file position) order."""
    keyed: list[tuple[float, int, int]] = []
    if profile.use_radar:
        keyed.extend((fr.t, 0, i) for i, fr in enumerate(flight.radar) if fr.tracks)
    if profile.use_rf:
        keyed.extend((a.t, 1, i) for i, a in enumerate(flight.rf) if a.ok)
    keyed.sort()
    return [flight.radar[i] if rank == 0 else flight.rf[i] for _, rank, i in keyed]


def input_info(flight: Flight, profile: Profile, reads: str) -> StreamInfo:
    """What an estimator reading ``reads`` (``selected`` or ``frames``) takes of ``flight``."""
    if reads == "selected":
        return selected_input(flight, profile)[1]
    reports = sum(len(fr.tracks) for fr in flight.radar) if profile.use_radar else 0
    fixes = sum(1 for a in flight.rf if a.ok and math.isfinite(a.e) and math.isfinite(a.n))
    return StreamInfo(
        radar_frames=len(flight.radar) if profile.use_radar else 0,
        radar_reports=reports,
        radar_selected=reports,
        not_selected=0,
        selected_track_id=None,
        rf_attempts=len(flight.rf) if profile.use_rf else 0,
        rf_fixes=fixes if profile.use_rf else 0,
    )


def build_stream(
    flight: Flight, profile: Profile, site: Site
) -> tuple[list[StreamItem], StreamInfo]:
    """:func:`selected_input` as measurements: with the largest-track selection every
    selected report on its own, otherwise each frame's reports as one candidate list; ``seq``
    numbers them in order."""
    del site  # the stream does not depend on the site; the estimator applies the range gate
    items, info = selected_input(flight, profile)
    largest = profile.radar_selection == "largest_track"
    out: list[StreamItem] = []
    seq = 0
    for item in items:
        if isinstance(item, RadarFrame):
            ms = [_radar_measurement(trk, seq + j) for j, trk in enumerate(item.tracks)]
            seq += len(ms)
            if largest:
                out.extend(ms)
            else:
                out.append(ms)
        else:
            out.append(
                Measurement(t=item.t, source=RF, z=np.array((item.e, item.n), float), seq=seq)
            )
            seq += 1
    return out, info


def flight_measurements(flight: Flight, profile: Profile, site: Site) -> list[StreamItem]:
    """Time-ordered stream: radar frames as candidate lists (online selection) or the
    selected track's reports as single measurements (largest-track selection); RF fixes
    with ``ok`` only. Deterministic ``seq`` numbers."""
    return build_stream(flight, profile, site)[0]


#: ``track_selection`` value meaning "the profile's own selection".
PROFILE_SELECTION = "profile"


def radar_profile(profile: str | Profile, track_selection: str = PROFILE_SELECTION) -> Profile:
    """The profile (a name, a path or a loaded one) with ``track_selection`` applied
    (``"profile"``: the profile's own selection)."""
    prof = profile if isinstance(profile, Profile) else load_profile(profile)
    if track_selection != PROFILE_SELECTION and track_selection != prof.radar_selection:
        prof = prof.with_changes(radar_selection=track_selection)
    return prof


def selected_radar(flight: Flight, profile: Profile, site: Site) -> list[list[Measurement]]:
    """The radar frames (lists of candidates, in order) the offline runner would feed."""
    frames: list[list[Measurement]] = []
    for item in flight_measurements(flight, profile, site):
        group = list(item) if isinstance(item, list) else [item]
        radar = [m for m in group if m.source == RADAR]
        if radar:
            frames.append(radar)
    return frames


def raw_radar_reports(flight: Flight, profile: Profile) -> list[RadarTrack]:
    """The UAV reports of the raw radar row (the profile's per-track mean rule)."""
    return uav_class_tracks(flight.radar, profile.raw_radar_min_mean_uav_prob)


def pose_covariance(profile: Profile, site: Site) -> Callable[[float, float, float], FloatArray]:
    """The 3x3 ENU covariance a radar pose message carries for a report at (e, n, u): the
    profile's fixed R (``measurement.radar.R``) when it has one, else its radar model's R
    there (a tracker profile with the polar model)."""
    from uav_fusion.core.estimators.parts import packed_to_array

    if profile.r_radar is not None:
        fixed = np.asarray(profile.r_radar, dtype=float)
        return lambda e, n, u: fixed
    cov = report_covariance(profile, site)
    return lambda e, n, u: packed_to_array(cov(e, n, u))


def report_covariance(profile: Profile, site: Site) -> Callable[[float, float, float], PackedR]:
    """The ENU covariance (packed upper triangle xx, xy, xz, yy, yz, zz) that ``profile``'s
    radar model gives a report at (e, n, u): the fixed R of the paper profile, the polar
    model's R of a tracker profile. Published with every report on ``radar/tracks``."""
    from uav_fusion.core.estimators.parts import radar_model_from_profile

    return radar_model_from_profile(profile, site).r_at
