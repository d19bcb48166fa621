"""The estimator: the paper's gated asynchronous constant-velocity Kalman filter, and the
tracker (every radar object scored, component filters, smoothing; ``tracker.py``).

Public API (pure Python + numpy/scipy, no ROS)::

    profile = load_profile("paper")              # config/profiles/paper.yaml
    result = run_flight(flight, profile, site)   # offline: RunResult(steps, counters)
    est = FusionEstimator(profile, site)          # streaming: what the ROS node wraps
    for item in flight_measurements(flight, profile, site):
        steps = est.process_frame(item) if isinstance(item, list) else est.process(item)
"""

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
    tracker_stream,
)
from uav_fusion.core.estimators.paper import STATUSES, FusionEstimator, Step
from uav_fusion.core.estimators.profile import Profile, load_profile, profile_from_dict
from uav_fusion.core.estimators.selection import (
    StreamInfo,
    build_stream,
    flight_measurements,
    largest_track_id,
)
from uav_fusion.core.estimators.tracker import Tracker, TrackerStep, TrackEstimate
from uav_fusion.core.scoring.noise import RNoiseEstimate, estimate_r

__all__ = [
    "STATUSES",
    "CvKalman",
    "FusionEstimator",
    "Profile",
    "RNoiseEstimate",
    "RunResult",
    "Step",
    "StreamInfo",
    "TrackEstimate",
    "Tracker",
    "TrackerStep",
    "build_stream",
    "cv_process_noise",
    "cv_transition",
    "estimate_r",
    "flight_measurements",
    "kf_predict",
    "kf_update_joseph",
    "largest_track_id",
    "load_profile",
    "pack_r",
    "position_h",
    "profile_from_dict",
    "run_flight",
    "run_stream",
    "run_tracker",
    "smooth_steps",
    "tracker_stream",
]
