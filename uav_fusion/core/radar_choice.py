"""Which radar reports go where: the radar track choice, defined once.

Two streams come out of a flight's radar file (``docs/graph.md``):

- the **selected** reports: the radar frames (lists of candidates sharing one stamp) the
  profile's track selection keeps, exactly the radar measurements the offline runner feeds the
  estimator (:func:`uav_fusion.core.estimator.flight_measurements`); with the paper's policy
  (``largest_track``) that is the largest continuous track, chosen with knowledge of the whole
  flight like the paper did;
- the **raw** reports: every report of the tracks classed as the UAV's by the profile's
  ``evaluation.raw_radar_min_mean_uav_prob`` (:mod:`uav_fusion.core.radar_class`), before
  selection: the evaluator's "radar raw" row.

A third stream carries every report of every frame, unselected: ``radar/tracks``
(:mod:`uav_fusion.core.clouds`), each report with the covariance of :func:`report_covariance`.

Users: ``radar_replay`` (``radar/pose``, ``radar/raw``, ``radar/tracks``), the bag converter
(the same three topics), ``uav_fusion evaluate`` and ``uav_fusion calibrate`` (the UAV-class
rule).
"""

from __future__ import annotations

from collections.abc import Callable

from uav_fusion.core.estimator import Profile, flight_measurements, load_profile
from uav_fusion.core.estimator.kalman import PackedR
from uav_fusion.core.radar_class import uav_class_tracks
from uav_fusion.core.records import RADAR, Flight, Measurement, RadarTrack
from uav_fusion.core.site import Site

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


def report_covariance(profile: Profile, site: Site) -> Callable[[float, float, float], PackedR]:
    """The ENU covariance (packed upper triangle xx, xy, xz, yy, yz, zz) that ``profile``'s
    radar model gives a report at (e, n, u): the fixed R of the paper profile, the polar
    model's R of a tracker profile. Published with every report on ``radar/tracks``."""
    from uav_fusion.core.estimator.tracker import radar_model_from_profile

    return radar_model_from_profile(profile, site).r_at
