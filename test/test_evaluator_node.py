"""evaluator_node in an in-process executor: fed messages (bad ones included), it writes the
report through its Trigger service, and its numbers equal the offline Evaluator's."""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import try_shutdown
from sensor_msgs.msg import NavSatFix
from std_srvs.srv import Trigger

from uav_fusion.core.records import TruthFix
from uav_fusion.core.scoring.evaluation import Evaluator
from uav_fusion.core.site import Site, load_site
from uav_fusion.nodes.evaluator_node import EvaluatorNode
from uav_fusion.ros.conversions import radar_to_msg, rf_to_msg, truth_to_navsatfix
from uav_fusion.ros.odometry import state_to_odometry

T0 = 1_760_000_000.0
R3 = np.diag([25.0, 25.0, 100.0])
P6 = np.diag([9.0, 9.0, 16.0, 1.0, 1.0, 1.0])


@dataclass
class Data:
    """Synthetic flight as message payloads plus the offline reference fed the same values."""

    truth: list[TruthFix] = field(default_factory=list)
    radar: list[tuple[float, np.ndarray]] = field(default_factory=list)
    rf: list[tuple[float, tuple[float, float] | None]] = field(default_factory=list)
    acc_radar: list[tuple[float, np.ndarray]] = field(default_factory=list)
    acc_rf: list[tuple[float, tuple[float, float]]] = field(default_factory=list)
    steps: list[tuple[float, str, np.ndarray]] = field(default_factory=list)


def make_data(site: Site) -> Data:
    rng = np.random.default_rng(11)
    d = Data()

    def pos(t: float) -> np.ndarray:
        s = t - T0
        return np.array([-100.0 + 8.0 * s, 300.0 - 3.0 * s, 40.0 + 0.1 * s])

    for k in range(121):  # 60 s of truth at 2 Hz
        t = T0 + 0.5 * k
        lat, lon, h = site.to_geodetic(*pos(t))
        e, n, u = site.to_enu(float(lat), float(lon), float(h))
        d.truth.append(
            TruthFix(t, float(lat), float(lon), float(h), float(e), float(n), float(u),
                     (0.0, 0.0, 0.0), 6, 20)
        )
    for k in range(200):
        t = T0 + 1.0 + 0.25 * k
        z = pos(t) + rng.normal(0.0, 6.0, 3)
        d.radar.append((t, z))
        if k % 5:
            d.acc_radar.append((t, z))
            d.steps.append((t, "updated", np.r_[z * 0.5 + pos(t) * 0.5, 8.0, -3.0, 0.1]))
        else:
            d.steps.append((t, "coasted", np.r_[pos(t) + rng.normal(0, 3, 3), 8.0, -3.0, 0.1]))
    for k in range(14):
        t = T0 + 2.0 + 3.88 * k
        if k % 6 == 5:
            d.rf.append((t, None))
            continue
        en = (float(pos(t)[0] + rng.normal(0, 40)), float(pos(t)[1] + rng.normal(0, 40)))
        d.rf.append((t, en))
        if k % 3:
            d.acc_rf.append((t, en))
    # the estimates that arrive after their truth: shift one step past the last truth sample
    d.steps.append((T0 + 70.0, "coasted", np.r_[pos(T0 + 70.0), 0.0, 0.0, 0.0]))
    return d


def offline(d: Data, site: Site, tol: float) -> Evaluator:
    ev = Evaluator(radar_enu=site.radar.enu, tolerance_s=tol)
    for f in d.truth:
        ev.add_truth(f.t, f.e, f.n, f.u)
    for t, z in d.radar:
        ev.add_radar_report(t, *z)
    for t, en in d.rf:
        if en is None:
            ev.add_rf_attempt(t, False)
        else:
            ev.add_rf_attempt(t, True, *en)
    for t, z in d.acc_radar:
        ev.add_validated(t, "radar", z)
    for t, en2 in d.acc_rf:
        ev.add_validated(t, "rf", en2)
    for t, status, x in d.steps:
        ev.add_step(t, status, x)
    return ev


@pytest.fixture
def ros() -> Iterator[None]:
    rclpy.init()
    try:
        yield
    finally:
        try_shutdown()


def spin_until(ex: SingleThreadedExecutor, cond: Callable[[], bool], timeout: float = 20.0) -> None:
    # A deadline, not a timing assertion: it only stops a hung test.
    import time

    end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > end:
            raise AssertionError("condition not reached before the deadline")
        ex.spin_once(timeout_sec=0.05)


def test_node_report_equals_offline_evaluator(ros: None, tmp_path: Path) -> None:
    site = load_site()
    frame = site.frame_id
    tol = 1.5
    out = tmp_path / "report"
    node = EvaluatorNode(
        parameter_overrides=[
            Parameter("output_dir", value=str(out)),
            Parameter("coverage_tolerance_s", value=tol),
            Parameter("log_period_s", value=0.2),
            Parameter("write_on_shutdown", value=False),
            Parameter("figures", value=True),
        ]
    )
    pub_node = Node("evaluator_test_feeder")
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    ex.add_node(pub_node)
    qos = QoSProfile(depth=1000, history=HistoryPolicy.KEEP_LAST,
                     reliability=ReliabilityPolicy.RELIABLE)
    pubs = {
        "truth": pub_node.create_publisher(NavSatFix, "truth/fix", qos),
        "radar": pub_node.create_publisher(PoseWithCovarianceStamped, "radar/raw", qos),
        "rf": pub_node.create_publisher(PointStamped, "rf/fix", qos),
        "acc_radar": pub_node.create_publisher(
            PoseWithCovarianceStamped, "fusion/accepted/radar", qos),
        "acc_rf": pub_node.create_publisher(PointStamped, "fusion/accepted/rf", qos),
        "updated": pub_node.create_publisher(Odometry, "fusion/odom/updated", qos),
        "coasted": pub_node.create_publisher(Odometry, "fusion/odom/coasted", qos),
    }
    diags: list[DiagnosticArray] = []
    pub_node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10)
    spin_until(ex, lambda: all(p.get_subscription_count() > 0 for p in pubs.values()))

    d = make_data(site)
    sent = 0

    def publish(key: str, msg: object) -> None:
        nonlocal sent
        pubs[key].publish(msg)
        sent += 1
        if sent % 50 == 0:  # let the subscriber keep up
            spin_until(ex, lambda: sum(node.received.values()) >= sent)

    # estimates first, truth last: scoring must not depend on arrival order
    for t, status, x in d.steps:
        publish(status, state_to_odometry(t, x, P6, frame, "uav"))
    for t, z in d.radar:
        publish("radar", radar_to_msg(t, z, R3, frame))
    for t, en in d.rf:
        publish("rf", rf_to_msg(t, en, frame))
    for t, z in d.acc_radar:
        publish("acc_radar", radar_to_msg(t, z, R3, frame))
    for t, en2 in d.acc_rf:
        publish("acc_rf", rf_to_msg(t, en2, frame))
    for f in d.truth:
        publish("truth", truth_to_navsatfix(f, "gps"))

    # bad messages: every one must be counted and dropped, none may crash the node
    bad_truth = truth_to_navsatfix(d.truth[3], "gps")
    bad_truth.latitude = math.nan
    publish("truth", bad_truth)
    bad_radar = radar_to_msg(T0 + 5.0, np.zeros(3), R3, frame)
    bad_radar.pose.pose.position.x = math.nan
    publish("radar", bad_radar)
    bad_cov = radar_to_msg(T0 + 5.0, np.zeros(3), R3, frame)
    bad_cov.pose.covariance[0] = -1.0
    publish("acc_radar", bad_cov)
    half_nan = rf_to_msg(T0 + 6.0, (1.0, 2.0), frame)
    half_nan.point.x = math.nan
    publish("rf", half_nan)
    publish("rf", rf_to_msg(T0 + 6.0, (1.0, 2.0), "some_other_frame"))
    publish("acc_rf", rf_to_msg(T0 + 6.0, None, frame))
    zero = state_to_odometry(T0 + 7.0, np.zeros(6), P6, frame, "uav")
    zero.header.stamp.sec = 0
    zero.header.stamp.nanosec = 0
    publish("updated", zero)
    nan_state = state_to_odometry(T0 + 7.0, np.zeros(6), P6, frame, "uav")
    nan_state.pose.pose.position.z = math.nan
    publish("coasted", nan_state)

    spin_until(ex, lambda: sum(node.received.values()) >= sent)
    spin_until(ex, lambda: len(diags) > 0)

    client = pub_node.create_client(Trigger, "evaluator_node/write_report")
    spin_until(ex, lambda: client.service_is_ready())
    future = client.call_async(Trigger.Request())
    spin_until(ex, future.done)
    resp = future.result()
    assert resp is not None and resp.success, resp
    assert Path(resp.message) == out / "report.md"

    doc = json.loads((out / "metrics.json").read_text())
    ref = offline(d, site, tol).evaluate()
    assert doc["rows"] == [r.as_dict() for r in ref.rows]
    assert doc["rf_attempts"] == 14 and doc["radar_reports"] == 200 and doc["steps"] == 201
    assert doc["dropped"] == {
        "truth/fix: nan": 1,
        "radar/raw: nan": 1,
        "fusion/accepted/radar: bad_covariance": 1,
        "rf/fix: nan": 1,
        "rf/fix: wrong_frame": 1,
        "fusion/accepted/rf: nan": 1,
        "fusion/odom/updated: zero_stamp": 1,
        "fusion/odom/coasted: nan": 1,  # a non-finite state is refused by the conversion
    }
    # the step published after the last truth sample is held, not scored against stale truth
    assert doc["rows"][4]["unscored"] == 1
    assert (out / "error_cdf.png").stat().st_size > 10_000
    md = (out / "report.md").read_text()
    assert "KF coasted estimates (3D)" in md and "live (evaluator_node)" in md

    names = [s.name for s in diags[-1].status]
    assert any("KF fused track, all steps" in n for n in names)
    assert any(n.endswith("inputs") for n in names)

    ex.shutdown()
    node.destroy_node()
    pub_node.destroy_node()


def test_write_report_failure_is_reported_not_raised(ros: None, tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    node = EvaluatorNode(
        parameter_overrides=[
            Parameter("output_dir", value=str(blocker / "sub")),
            Parameter("write_on_shutdown", value=False),
            Parameter("log_period_s", value=0.0),
        ]
    )
    resp = node._on_write_report(Trigger.Request(), Trigger.Response())
    assert not resp.success
    assert "cannot create the report folder" in resp.message
    node.destroy_node()


def test_bad_parameters_are_refused_with_their_name(ros: None) -> None:
    from uav_fusion.ros.params import ParamError

    with pytest.raises(ParamError, match="coverage_tolerance_s"):
        EvaluatorNode(parameter_overrides=[Parameter("coverage_tolerance_s", value=-1.0)])
    with pytest.raises(ParamError, match="truth_topic"):
        EvaluatorNode(parameter_overrides=[Parameter("truth_topic", value=" ")])


def test_output_dir_can_change_at_run_time(ros: None, tmp_path: Path) -> None:
    node = EvaluatorNode(
        parameter_overrides=[
            Parameter("output_dir", value=str(tmp_path / "a")),
            Parameter("write_on_shutdown", value=False),
            Parameter("log_period_s", value=0.0),
            Parameter("figures", value=False),
        ]
    )
    res = node.set_parameters([Parameter("output_dir", value=str(tmp_path / "b"))])
    assert res[0].successful
    assert not node.set_parameters([Parameter("coverage_tolerance_s", value=2.0)])[0].successful
    files = node.write_report()
    assert files.folder == tmp_path / "b" and files.json.is_file()
    node.destroy_node()


def test_rcs_comes_from_the_flight_folder_when_given(ros: None, tmp_path: Path) -> None:
    """Pose messages carry no RCS; with ``rcs_flight_dir`` each raw report gets its own."""
    from test_graph_flight import write_flight

    from uav_fusion.core.data import load_flight
    from uav_fusion.ros.conversions import radar_track_to_msg

    site = load_site()
    folder = write_flight(tmp_path / "flight", seconds=10.0)
    tracks = [trk for f in load_flight(folder, site).radar for trk in f.tracks]
    assert {t.rcs_dbsm for t in tracks} == {-12.0, -25.0, None}  # UAV, clutter, no RCS
    node = EvaluatorNode(parameter_overrides=[
        Parameter("rcs_flight_dir", value=str(folder)),
        Parameter("output_dir", value=str(tmp_path / "rep")),
    ])
    plain = EvaluatorNode(parameter_overrides=[Parameter("output_dir", value=str(tmp_path / "r2"))])
    try:
        for trk in tracks:
            msg = radar_track_to_msg(trk, R3, site.frame_id)
            node._on_radar_raw(msg)
            plain._on_radar_raw(msg)
        got = node.evaluate().radar_rcs_dbsm
        want = [t.rcs_dbsm for t in tracks if t.rcs_dbsm is not None]
        assert sorted(got[np.isfinite(got)].tolist()) == sorted(want)
        assert int(np.isnan(got).sum()) == len(tracks) - len(want)
        assert np.isnan(plain.evaluate().radar_rcs_dbsm).all()
        files = node.write_report()
        assert (files.folder / "radar_rcs_histogram.png").is_file()
    finally:
        node.destroy_node()
        plain.destroy_node()
