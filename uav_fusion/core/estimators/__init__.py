"""The estimators: the paper's gated asynchronous constant-velocity Kalman filter, the
single-UAV tracker and the multi-UAV tracker, behind one interface (:mod:`.base`).

Public API (pure Python + numpy/scipy, no ROS)::

    profile = load_profile("tracker")                # config/profiles/tracker.yaml
    result = run_flight(flight, profile, site)       # offline: RunResult(steps, grid, counters)
    est = make_estimator(profile, site, grid_hz=10)  # streaming: what the fusion node drives
    for item in est.flight_input(flight):            # radar frames and RF attempts, time order
        out = feed(est, item)                        # Outputs(steps, grid, tracks, smoothed)
"""

from uav_fusion.core.estimators.base import ESTIMATORS, Estimator, drive, feed, make_estimator
from uav_fusion.core.estimators.grid import Outputs
from uav_fusion.core.estimators.kalman import CvKalman, pack_r
from uav_fusion.core.estimators.models import (
    cv_process_noise,
    cv_transition,
    kf_predict,
    kf_update_joseph,
    position_h,
)
from uav_fusion.core.estimators.offline import (
    RunResult,
    run_flight,
    run_stream,
    run_tracker,
    smooth_steps,
)
from uav_fusion.core.estimators.paper import FusionEstimator
from uav_fusion.core.estimators.selection import (
    StreamInfo,
    build_stream,
    flight_measurements,
    frames_input,
    largest_track_id,
)
from uav_fusion.core.estimators.steps import STATUSES, Step, TrackerStep
from uav_fusion.core.estimators.tracker import Tracker, TrackEstimate
from uav_fusion.core.profiles.model import Profile, load_profile, profile_from_dict

__all__ = [
    "ESTIMATORS",
    "STATUSES",
    "CvKalman",
    "Estimator",
    "FusionEstimator",
    "Outputs",
    "Profile",
    "RunResult",
    "Step",
    "StreamInfo",
    "TrackEstimate",
    "Tracker",
    "TrackerStep",
    "build_stream",
    "cv_process_noise",
    "cv_transition",
    "drive",
    "feed",
    "flight_measurements",
    "frames_input",
    "kf_predict",
    "kf_update_joseph",
    "largest_track_id",
    "load_profile",
    "make_estimator",
    "pack_r",
    "position_h",
    "profile_from_dict",
    "run_flight",
    "run_stream",
    "run_tracker",
    "smooth_steps",
]
