"""radar_replay and rf_replay publish every report and attempt as PointCloud2 (radar/tracks,
rf/fixes) next to the paper profile's topics, losslessly."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import PointCloud2
from test_graph_flight import write_flight
from test_replay_nodes import Collector, _params, spin_until

from uav_fusion.core.data import load_flight
from uav_fusion.nodes.radar_replay import RadarReplay
from uav_fusion.nodes.rf_replay import RfReplay
from uav_fusion.ros import conversions as cv


@pytest.fixture(scope="module")
def flight_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_flight(tmp_path_factory.mktemp("flight") / "clouds", seconds=20.0)


def test_every_report_and_attempt_is_published_as_a_cloud(
    ctx: Context, flight_dir: Path
) -> None:
    flight = load_flight(flight_dir)
    common = {"flight_dir": str(flight_dir), "rate": 0.0, "wait_for_subscribers_s": 5.0}
    radar = RadarReplay(context=ctx, parameter_overrides=_params(profile="tracker", **common))
    rf = RfReplay(context=ctx, parameter_overrides=_params(**common))
    col = Collector(ctx, {"radar/tracks": PointCloud2, "rf/fixes": PointCloud2})
    ex = SingleThreadedExecutor(context=ctx)
    for n in (radar, rf, col):
        ex.add_node(n)
    radar.start_standalone()
    rf.start_standalone()
    spin_until(
        ex,
        lambda: len(col.got["radar/tracks"]) == len(flight.radar)
        and len(col.got["rf/fixes"]) == len(flight.rf),
    )
    for fr, msg in zip(flight.radar, col.got["radar/tracks"], strict=True):
        got, dropped = cv.msg_to_radar_frame(msg, radar.site.frame_id)
        assert not dropped and got.t == fr.t
        assert [(t.track_id, t.e, t.n, t.u, t.vel_ned, t.uav_prob) for t in got.tracks] == [
            (t.track_id, t.e, t.n, t.u, t.vel_ned, t.uav_prob) for t in fr.tracks
        ]
    for a, msg in zip(flight.rf, col.got["rf/fixes"], strict=True):
        (b,), dropped = cv.msg_to_rf_attempts(msg, rf.site.frame_id)
        assert not dropped and (b.t, b.ok, b.cep, b.meas_id) == (a.t, a.ok, a.cep, a.meas_id)
    for n in (radar, rf, col):
        n.destroy_node()


def test_the_clouds_can_be_switched_off(ctx: Context, flight_dir: Path) -> None:
    radar = RadarReplay(
        context=ctx, parameter_overrides=_params(flight_dir=str(flight_dir), publish_tracks=False)
    )
    rf = RfReplay(
        context=ctx, parameter_overrides=_params(flight_dir=str(flight_dir), publish_fixes=False)
    )
    assert radar.pub_tracks is None and rf.pub_fixes is None
    assert len(radar.streams()) == 2 and len(rf.streams()) == 1
    for n in (radar, rf):
        n.destroy_node()


def test_a_reader_of_either_encoding_starts_the_replay(ctx: Context, flight_dir: Path) -> None:
    """radar/pose and radar/tracks carry one stream: a graph reads one of them, so the replay
    does not wait for a reader of the other (nor rf/fix for one of rf/fixes)."""
    flight = load_flight(flight_dir)
    radar = RadarReplay(context=ctx, parameter_overrides=_params(
        flight_dir=str(flight_dir), rate=0.0, wait_for_subscribers_s=60.0, publish_raw=False))
    col = Collector(ctx, {"radar/tracks": PointCloud2})
    ex = SingleThreadedExecutor(context=ctx)
    for n in (radar, col):
        ex.add_node(n)
    radar.start_standalone()
    t0 = time.monotonic()
    spin_until(ex, lambda: len(col.got["radar/tracks"]) == len(flight.radar))
    assert time.monotonic() - t0 < 30.0  # well before the 60 s wait would have ended
    assert radar.pub.get_subscription_count() == 0
    for n in (radar, col):
        n.destroy_node()
