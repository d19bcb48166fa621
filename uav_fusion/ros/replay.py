"""The replay timeline shared by radar_replay, rf_replay and truth_replay.

A replay publishes recorded messages stamped with their sensor (UTC) time. When they are
*published* is decided by a :class:`ReplayDriver`:

- ``rate > 0``: sensor time advances ``rate`` times as fast as the wall clock from the
  flight's first time (1.0 = real time); every event whose time (plus the stream's
  ``delay_s``) has been reached is published.
- ``rate = 0``: as fast as the subscribers keep up, without loss: a batch of at most
  ``batch_size`` events is published only after every earlier message was acknowledged by the
  subscribers (reliable QoS) and, inside one process, after the consumers report they have
  taken them (``drained`` hook, used by ``graph``).
- *follow*: a replay that does not publish ``/clock`` but runs with ``use_sim_time`` publishes
  every event whose time has been reached by the simulated clock, so several replay
  processes share the timeline of the one that publishes ``/clock``.

The driver that publishes ``/clock`` sends the current sensor time there (``rosgraph_msgs/
Clock``); with ``rate > 0`` it keeps advancing after the last event so that time-driven
consumers (reorder windows) see time pass. Before the first event, a driver waits until
every data publisher has at least one subscriber, for up to ``wait_for_subscribers_s``.

In ``graph`` all three replays register their events with one driver, which publishes them
in one global time order.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rclpy.clock import Clock as RosClock
from rclpy.clock_type import ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.publisher import Publisher
from rosgraph_msgs.msg import Clock

from uav_fusion.core.data import load_flight
from uav_fusion.core.records import Flight
from uav_fusion.core.site import Site, load_site
from uav_fusion.resources import DEFAULT_FLIGHT, data_path
from uav_fusion.ros.app import run_node
from uav_fusion.ros.conversions import ns_to_time, stamp_from_time
from uav_fusion.ros.params import Param, declare_all
from uav_fusion.ros.qos import CLOCK_QOS, stream_qos


def replay_params(publish_clock: bool) -> list[Param]:
    """Parameters every replay node declares."""
    return [
        Param("flight_dir", "", "flight folder in the Dataset-28 layout ('' = bundled default)"),
        Param("site_file", "", "site YAML ('' = bundled Lake Wheeler site)"),
        Param("frame_id", "", "ENU frame id of published positions ('' = the site's frame_id)"),
        Param(
            "rate",
            1.0,
            "replay speed: 1.0 real time, >1 faster, 0 = as fast as lossless",
            lo=0.0,
            hi=10000.0,
            read_only=True,
        ),
        Param("publish_clock", publish_clock, "publish /clock (drive the shared timeline)"),
        Param(
            "clock_period_s",
            0.02,
            "wall seconds between /clock messages and timer ticks",
            lo=0.001,
            hi=1.0,
        ),
        Param(
            "wait_for_subscribers_s",
            10.0,
            "wall seconds to wait for subscribers before the first message (0 = do not wait)",
            lo=0.0,
            hi=3600.0,
        ),
        Param(
            "wait_for_clock_subscribers",
            0,
            "with publish_clock: also wait (same timeout) until /clock has this many "
            "subscribers, e.g. the follower replays and the fusion node in other processes",
            lo=0,
            hi=1000,
        ),
        Param(
            "min_subscribers",
            1,
            "before the first message, also wait (same timeout) until every stream has this "
            "many subscribers, e.g. 2 when fusion_node and evaluator_node both read it",
            lo=1,
            hi=1000,
        ),
        Param(
            "delay_s",
            0.0,
            "publish each message this many sensor seconds after its stamp (tests lateness)",
            lo=0.0,
            hi=3600.0,
        ),
        Param("batch_size", 50, "most events per batch when rate = 0", lo=1, hi=100000),
        Param(
            "batch_span_s",
            1.0,
            "most sensor seconds one batch spans when rate = 0 (keep below the fusion "
            "node's reorder_window_s)",
            lo=0.0,
            hi=3600.0,
        ),
        Param("qos_depth", 1000, "history depth of the reliable streams", lo=1, hi=1000000),
        Param(
            "exit_when_done",
            False,
            "stop the node once every message is published and acknowledged",
        ),
    ]


def load_replay_flight(flight_dir: str, site_file: str) -> tuple[Site, Flight]:
    """The site and the flight a replay node works on (bundled defaults for '')."""
    site = load_site(site_file or None)
    folder = Path(flight_dir) if flight_dir else data_path(DEFAULT_FLIGHT)
    return site, load_flight(folder, site)


def flight_span(flight: Flight) -> tuple[float, float]:
    """First and last time of any record of the flight."""
    ts = [f.t for f in flight.truth] + [f.t for f in flight.radar] + [a.t for a in flight.rf]
    if not ts:
        return 0.0, 0.0
    return min(ts), max(ts)


@dataclass(order=True)
class ReplayEvent:
    """One message to publish: when (sensor time ``due``), in which order, where and what."""

    due: float
    order: int
    publisher: Publisher = field(compare=False)
    msg: Any = field(compare=False)


class ReplayDriver:
    """Publishes :class:`ReplayEvent` s on one timeline from a timer of ``node``."""

    def __init__(
        self,
        node: Node,
        *,
        rate: float,
        publish_clock: bool,
        clock_period_s: float,
        wait_for_subscribers_s: float,
        batch_size: int,
        span: tuple[float, float],
        batch_span_s: float = math.inf,
        follow_sim_time: bool = False,
        clock_subscribers: int = 0,
        min_subscribers: int = 1,
        drained: Callable[[], bool] | None = None,
        on_done: Callable[[], None] | None = None,
    ) -> None:
        self.node = node
        self.rate = float(rate)
        self.follow = bool(follow_sim_time) and not publish_clock
        self.batch_size = int(batch_size)
        self.batch_span_s = float(batch_span_s)
        self.wait_s = float(wait_for_subscribers_s)
        self.t_start, self.t_end = span
        self.drained = drained
        self.clock_subscribers = int(clock_subscribers)
        self.min_subscribers = int(min_subscribers)
        self.on_done = on_done
        self.events: list[ReplayEvent] = []
        self._publishers: list[Publisher] = []
        # id(publisher) -> the publishers of the same data in another encoding
        self._alternatives: dict[int, list[Publisher]] = {}
        self.published: dict[int, int] = {}  # id(publisher) -> messages published
        self._next = 0
        self._order = 0
        self._state = "idle"
        self._wall0 = 0.0
        self._last_tick = 0.0
        self._wait_started = 0.0
        self._clock_t = -math.inf
        self.done = False
        self.clock_pub = (
            node.create_publisher(Clock, "/clock", CLOCK_QOS) if publish_clock else None
        )
        self._period = float(clock_period_s)
        # wall-clock (steady) timer: with use_sim_time a ROS-time timer would only tick once
        # /clock runs, and a follower must be ready before that
        steady = RosClock(clock_type=ClockType.STEADY_TIME)
        self._timer = node.create_timer(self._period, self._tick, clock=steady)

    # --- set-up ---------------------------------------------------------------------------
    def add(
        self, publisher: Publisher, items: Sequence[tuple[float, Any]], delay_s: float = 0.0
    ) -> None:
        """Register messages (sensor time, message) for ``publisher``; keeps their order."""
        if self._state != "idle":
            raise RuntimeError("events must be added before the replay starts")
        if publisher not in self._publishers:
            self._publishers.append(publisher)
            self.published[id(publisher)] = 0
        for t, msg in items:
            self.events.append(ReplayEvent(t + delay_s, self._order, publisher, msg))
            self._order += 1

    def alternatives(self, *publishers: Publisher) -> None:
        """Declare ``publishers`` as one stream in several encodings (``radar/pose`` and
        ``radar/tracks``): the wait for subscribers is satisfied for all of them as soon as
        one has its subscribers (a graph reads one encoding, not every one)."""
        for p in publishers:
            self._alternatives[id(p)] = [q for q in publishers if q is not p]

    def start(self) -> None:
        """Sort the timeline and begin (waiting for subscribers first)."""
        self.events.sort()
        self._state = "waiting"
        self._wait_started = time.monotonic()
        if self.events:
            self.t_start = min(self.t_start, self.events[0].due)
        if self.clock_pub is not None:
            self._publish_clock(self.t_start)

    # --- progress -------------------------------------------------------------------------
    @property
    def remaining(self) -> int:
        return len(self.events) - self._next

    def published_to(self, publisher: Publisher) -> int:
        return self.published.get(id(publisher), 0)

    def _subscribers_ready(self) -> bool:
        if (
            self.clock_pub is not None
            and self.clock_pub.get_subscription_count() < self.clock_subscribers
        ):
            return False
        return not self._missing_subscribers()

    def _missing_subscribers(self) -> list[Publisher]:
        n = max(1, self.min_subscribers)
        ready = {id(p) for p in self._publishers if p.get_subscription_count() >= n}
        return [
            p
            for p in self._publishers
            if id(p) not in ready
            and not any(id(q) in ready for q in self._alternatives.get(id(p), []))
        ]

    def _publish_clock(self, t: float) -> None:
        if self.clock_pub is None or t <= self._clock_t:
            return
        self._clock_t = t
        msg = Clock()
        msg.clock = stamp_from_time(t)
        self.clock_pub.publish(msg)

    def _horizon(self) -> float:
        if self.follow:
            ns = self.node.get_clock().now().nanoseconds
            return -math.inf if ns == 0 else ns_to_time(ns)
        if self.rate == 0.0:
            return math.inf
        return self.t_start + (time.monotonic() - self._wall0) * self.rate

    def _all_acked(self) -> bool:
        zero = Duration(seconds=0)
        return all(p.wait_for_all_acked(zero) for p in self._publishers)

    def _tick(self) -> None:
        if self._state == "finished":
            if self.clock_pub is not None and self.rate > 0.0:
                self._publish_clock(self._horizon())  # time goes on after the last event
            return
        if self._state == "waiting":
            ready = self._subscribers_ready()
            if not ready and time.monotonic() - self._wait_started < self.wait_s:
                return
            if not ready:
                n = max(1, self.min_subscribers)
                missing = [p.topic_name for p in self._missing_subscribers()]
                what = "no subscriber" if n == 1 else f"fewer than {n} subscribers"
                self.node.get_logger().warning(
                    f"{what} after {self.wait_s:g} s on {', '.join(missing)}; "
                    "publishing anyway"
                )
            self._state = "running"
            self._wall0 = self._last_tick = time.monotonic()
            self.node.get_logger().info(
                f"replaying {len(self.events)} messages at rate {self.rate:g}"
                + (" following /clock" if self.follow else "")
            )
        if self._state == "running":
            self._run()

    def _run(self) -> None:
        limit = len(self.events)
        horizon = self._horizon()
        if self.rate == 0.0 and not self.follow:
            # consumers in this process: "taken" is stronger than "acknowledged"
            ready = self.drained() if self.drained is not None else self._all_acked()
            if not ready:
                return
            limit = self.batch_size
            if self._next < len(self.events):
                horizon = self.events[self._next].due + self.batch_span_s
        elif self.drained is not None and not self.follow:
            # paced, with consumers in this process: sensor time stands still while they
            # catch up, and one tick never spans more than batch_span_s (after a stall)
            now = time.monotonic()
            if not self.drained():
                self._wall0 += now - self._last_tick
                self._last_tick = now
                return
            if self._next < len(self.events):
                cap = max(self.events[self._next].due, self._clock_t) + self.batch_span_s
                if horizon > cap:
                    self._wall0 += (horizon - cap) / self.rate
                    horizon = cap
            self._last_tick = now
        n = 0
        while self._next < len(self.events) and n < limit:
            ev = self.events[self._next]
            if ev.due > horizon:
                break
            self._publish_clock(ev.due)  # the clock never runs ahead of a pending event
            ev.publisher.publish(ev.msg)
            self.published[id(ev.publisher)] += 1
            self._next += 1
            n += 1
        if self.rate > 0.0 and not self.follow:
            self._publish_clock(horizon)  # real-time pacing: time passes between events
        if self._next >= len(self.events):
            self._state = "finished"
            self.done = True
            self._publish_clock(self.t_end)
            per_topic = ", ".join(
                f"{p.topic_name} {self.published[id(p)]}" for p in self._publishers
            )
            # the sent counts a receiver's accounting is checked against (scripts/multihost.py)
            self.node.get_logger().info(
                f"replay finished: {len(self.events)} messages sent ({per_topic})"
            )
            if self.on_done is not None:
                self.on_done()

    def wait_acked(self, timeout_s: float) -> bool:
        """Block until every published message is acknowledged (or the timeout passes)."""
        deadline = Duration(seconds=timeout_s)
        return all(p.wait_for_all_acked(deadline) for p in self._publishers)

    def destroy(self) -> None:
        self._timer.cancel()
        self.node.destroy_timer(self._timer)


class ReplayNode(Node):
    """Base of the replay nodes: parameters, the flight, and a driver of its own (or none).

    Subclasses implement :meth:`streams`. Stand-alone (``ros2 run``), a node builds its own
    :class:`ReplayDriver` with :meth:`start_standalone`; inside ``graph`` the caller hands the
    streams of all replays to one shared driver instead.
    """

    def __init__(
        self,
        name: str,
        publish_clock: bool,
        extra: Sequence[Param] = (),
        **kwargs: Any,
    ) -> None:
        super().__init__(name, **kwargs)
        self.p = declare_all(self, [*replay_params(publish_clock), *extra])
        self.site, self.flight = load_replay_flight(self.p["flight_dir"], self.p["site_file"])
        self.frame_id: str = self.p["frame_id"] or self.site.frame_id
        self.qos = stream_qos(int(self.p["qos_depth"]))
        self.driver: ReplayDriver | None = None
        self.finished = False

    def streams(self) -> list[tuple[Publisher, list[tuple[float, Any]]]]:
        """(publisher, [(sensor time, message), ...]) of every stream this node replays."""
        raise NotImplementedError

    def alternatives(self) -> list[tuple[Publisher, ...]]:
        """Groups of publishers that carry one stream in several encodings (see
        :meth:`ReplayDriver.alternatives`)."""
        return []

    def use_sim_time(self) -> bool:
        return bool(self.get_parameter("use_sim_time").value)

    def start_standalone(self) -> ReplayDriver:
        """Build this node's own driver, register its streams and start."""
        drv = ReplayDriver(
            self,
            rate=float(self.p["rate"]),
            publish_clock=bool(self.p["publish_clock"]),
            clock_period_s=float(self.p["clock_period_s"]),
            wait_for_subscribers_s=float(self.p["wait_for_subscribers_s"]),
            batch_size=int(self.p["batch_size"]),
            span=flight_span(self.flight),
            batch_span_s=float(self.p["batch_span_s"]),
            follow_sim_time=self.use_sim_time(),
            clock_subscribers=int(self.p["wait_for_clock_subscribers"]),
            min_subscribers=int(self.p["min_subscribers"]),
            on_done=self._on_done,
        )
        for pub, items in self.streams():
            drv.add(pub, items, float(self.p["delay_s"]))
        for group in self.alternatives():
            drv.alternatives(*group)
        drv.start()
        self.driver = drv
        return drv

    def _on_done(self) -> None:
        self.finished = True


def run_replay(
    factory: Callable[..., ReplayNode], args: Sequence[str] | None = None, name: str = "replay"
) -> int:
    """``main()`` body of a replay node: start, spin, stop cleanly; 2 on a bad set-up."""

    def start(node: Node) -> None:
        assert isinstance(node, ReplayNode)
        node.start_standalone()

    def finished(node: Node) -> bool:
        assert isinstance(node, ReplayNode)
        return node.finished and bool(node.p["exit_when_done"])

    def on_stop(node: Node, _executor: Any) -> None:
        assert isinstance(node, ReplayNode)
        if node.finished and node.driver is not None and node.context.ok():
            node.driver.wait_acked(5.0)

    return run_node(factory, args, start=start, finished=finished, on_stop=on_stop, name=name)
