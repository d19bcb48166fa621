"""The views of the fusion: ``visualization_msgs/MarkerArray`` layers, all in the world frame.

One :class:`Visualization` holds an ordered list of layers; each layer owns one or more marker
namespaces and returns its markers with fixed ids, so a layer that draws the same things again
replaces them in RViz / Foxglove. Layers today:

=====================  ======================  ==============================================
layer                  namespace(s)            what
=====================  ======================  ==============================================
:class:`SiteLayer`     ``towers``,             a cylinder per tower (ground to antenna) with
                       ``tower_names``,        its name; the radar's range gate as a circle
                       ``radar_gate``          at the radar's height
:class:`TrackLayer`    ``track``,              the fused position (sphere) and its position
                       ``track_covariance``    covariance as a ``sigma``-sigma ellipsoid
:class:`ReportLayer`   ``radar_accepted``,     the last ``history`` radar reports that passed
                       ``radar_rejected``,     every gate / were refused, and RF fixes
                       ``rf_fixes``            (blue used, orange refused)
:class:`TracksLayer`   ``tracks``,             every confirmed UAV track of the multi-UAV
                       ``tracks_covariance``,  tracker (marker id = track id): position,
                       ``tracks_label``,       covariance ellipsoid, "<id> p=<UAV
                       ``tracks_trail``        probability>" label and its recent trail; a
                                               track that ended is deleted
=====================  ======================  ==============================================

Layers never share a namespace. No ``/tf`` is published (no tf2 message package is installed
with the wheels): every marker carries the world frame id (the site's ENU frame,
``enu_lw1``), which RViz accepts as its fixed frame.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Sequence
from typing import Protocol

import numpy as np
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point, Quaternion, Vector3
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from uav_fusion.core.site import Site


def rgba(r: float, g: float, b: float, a: float = 1.0) -> ColorRGBA:
    return ColorRGBA(r=float(r), g=float(g), b=float(b), a=float(a))


GREEN = rgba(0.1, 0.8, 0.2)
RED = rgba(0.9, 0.15, 0.1)
BLUE = rgba(0.15, 0.35, 0.95)
ORANGE = rgba(1.0, 0.55, 0.0)
GREY = rgba(0.6, 0.6, 0.6)
TRACK = rgba(1.0, 0.85, 0.0)
ELLIPSOID = rgba(1.0, 0.85, 0.0, 0.35)


class MarkerLayer(Protocol):
    """A layer: its markers for one stamp and frame (fixed ids per namespace)."""

    namespaces: tuple[str, ...]

    def markers(self, stamp: Time, frame_id: str) -> list[Marker]: ...


def _marker(ns: str, mid: int, kind: int, stamp: Time, frame_id: str) -> Marker:
    m = Marker()
    m.header.stamp = stamp
    m.header.frame_id = frame_id
    m.ns = ns
    m.id = mid
    m.type = kind
    m.action = Marker.ADD
    m.pose.orientation.w = 1.0
    m.lifetime = Duration(sec=0, nanosec=0)  # until replaced
    return m


def _pt(x: float, y: float, z: float) -> Point:
    return Point(x=float(x), y=float(y), z=float(z))


def ellipsoid_pose(cov: Sequence[Sequence[float]], sigma: float) -> tuple[
    tuple[float, float, float], tuple[float, float, float, float]
]:
    """Diameters (x, y, z) and orientation quaternion (x, y, z, w) of the ``sigma``-sigma
    ellipsoid of a 3x3 covariance (principal axes from its eigenvectors)."""
    c = np.asarray(cov, dtype=float)
    c = 0.5 * (c + c.T)
    w, v = np.linalg.eigh(c)
    if np.linalg.det(v) < 0:  # a proper rotation
        v[:, 2] = -v[:, 2]
    d = tuple(2.0 * sigma * math.sqrt(max(float(x), 0.0)) for x in w)
    return (d[0], d[1], d[2]), rotation_to_quaternion(v)


def rotation_to_quaternion(r: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a 3x3 rotation matrix."""
    m = r
    tr = float(m[0, 0] + m[1, 1] + m[2, 2])
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        return ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s,
                0.25 * s)
    i = int(np.argmax([m[0, 0], m[1, 1], m[2, 2]]))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * math.sqrt(max(1.0 + m[i, i] - m[j, j] - m[k, k], 1e-300))
    q = [0.0, 0.0, 0.0]
    q[i] = 0.25 * s
    q[j] = (m[j, i] + m[i, j]) / s
    q[k] = (m[k, i] + m[i, k]) / s
    return (float(q[0]), float(q[1]), float(q[2]), float((m[k, j] - m[j, k]) / s))


class SiteLayer:
    """Towers (cylinder + name) and the radar's range gate (circle)."""

    namespaces: tuple[str, ...] = ("towers", "tower_names", "radar_gate")

    def __init__(self, site: Site, range_gate_m: float | None = None, segments: int = 128):
        self.site = site
        self.range_gate_m = float(
            site.radar.range_gate_m if range_gate_m is None else range_gate_m
        )
        self.segments = segments

    def markers(self, stamp: Time, frame_id: str) -> list[Marker]:
        out: list[Marker] = []
        for k, (name, tw) in enumerate(sorted(self.site.towers.items())):
            e, n, top = tw.enu
            height = max(float(tw.antenna_agl), 1.0)
            c = _marker("towers", k, Marker.CYLINDER, stamp, frame_id)
            c.pose.position = _pt(e, n, top - height / 2.0)
            c.scale = Vector3(x=4.0, y=4.0, z=height)
            c.color = BLUE if name in self.site.rf_sensors else GREY
            out.append(c)
            t = _marker("tower_names", k, Marker.TEXT_VIEW_FACING, stamp, frame_id)
            t.pose.position = _pt(e, n, top + 8.0)
            t.scale.z = 12.0
            t.color = rgba(1.0, 1.0, 1.0)
            t.text = name
            out.append(t)
        g = _marker("radar_gate", 0, Marker.LINE_STRIP, stamp, frame_id)
        re, rn, ru = self.site.radar.enu
        r = self.range_gate_m
        g.points = [
            _pt(re + r * math.cos(a), rn + r * math.sin(a), ru)
            for a in (2.0 * math.pi * i / self.segments for i in range(self.segments + 1))
        ]
        g.scale.x = 2.0
        g.color = RED
        out.append(g)
        return out


class TrackLayer:
    """The fused position and its position covariance ellipsoid."""

    def __init__(self, namespace: str = "track", sigma: float = 2.0, radius_m: float = 6.0):
        self.namespace = namespace
        self.namespaces: tuple[str, ...] = (namespace, f"{namespace}_covariance")
        self.sigma = sigma
        self.radius_m = radius_m
        self.position: tuple[float, float, float] | None = None
        self.cov: list[list[float]] | None = None

    def update(self, position: Sequence[float], cov: Sequence[Sequence[float]]) -> None:
        self.position = (float(position[0]), float(position[1]), float(position[2]))
        self.cov = [[float(v) for v in row[:3]] for row in cov[:3]]

    def markers(self, stamp: Time, frame_id: str) -> list[Marker]:
        if self.position is None or self.cov is None:
            return []
        s = _marker(self.namespace, 0, Marker.SPHERE, stamp, frame_id)
        s.pose.position = _pt(*self.position)
        d = 2.0 * self.radius_m
        s.scale = Vector3(x=d, y=d, z=d)
        s.color = TRACK
        e = _marker(f"{self.namespace}_covariance", 0, Marker.SPHERE, stamp, frame_id)
        e.pose.position = _pt(*self.position)
        (dx, dy, dz), (qx, qy, qz, qw) = ellipsoid_pose(self.cov, self.sigma)
        e.scale = Vector3(x=max(dx, 0.01), y=max(dy, 0.01), z=max(dz, 0.01))
        e.pose.orientation = Quaternion(x=qx, y=qy, z=qz, w=qw)
        e.color = ELLIPSOID
        return [s, e]


class TracksLayer:
    """Every confirmed track of the multi-UAV tracker (see the module table)."""

    def __init__(self, sigma: float = 2.0, radius_m: float = 6.0, trail: int = 100) -> None:
        self.namespaces: tuple[str, ...] = (
            "tracks", "tracks_covariance", "tracks_label", "tracks_trail",
        )  # fmt: skip
        self.sigma = sigma
        self.radius_m = radius_m
        self.trail_len = trail
        self._now: dict[int, tuple[tuple[float, float, float], list[list[float]], float]] = {}
        self._trails: dict[int, deque[tuple[float, float, float]]] = {}
        self._gone: set[int] = set()

    def update(
        self, tracks: Iterable[tuple[int, Sequence[float], Sequence[Sequence[float]], float]]
    ) -> None:
        """The confirmed tracks now: (id, position, 3x3 covariance, UAV probability)."""
        now: dict[int, tuple[tuple[float, float, float], list[list[float]], float]] = {}
        for tid, pos, cov, prob in tracks:
            p = (float(pos[0]), float(pos[1]), float(pos[2]))
            now[int(tid)] = (p, [[float(v) for v in row[:3]] for row in cov[:3]], float(prob))
            trail = self._trails.setdefault(int(tid), deque(maxlen=self.trail_len))
            trail.append(p)
        self._gone |= set(self._now) - set(now)
        for tid in set(self._trails) - set(now):
            del self._trails[tid]
        self._now = now

    def markers(self, stamp: Time, frame_id: str) -> list[Marker]:
        out: list[Marker] = []
        for tid in sorted(self._gone):  # ended tracks: remove their markers
            for ns in self.namespaces:
                m = _marker(ns, tid, Marker.SPHERE, stamp, frame_id)
                m.action = Marker.DELETE
                out.append(m)
        self._gone.clear()
        d = 2.0 * self.radius_m
        for tid, (p, cov, prob) in sorted(self._now.items()):
            s = _marker("tracks", tid, Marker.SPHERE, stamp, frame_id)
            s.pose.position = _pt(*p)
            s.scale = Vector3(x=d, y=d, z=d)
            s.color = TRACK
            e = _marker("tracks_covariance", tid, Marker.SPHERE, stamp, frame_id)
            e.pose.position = _pt(*p)
            (dx, dy, dz), (qx, qy, qz, qw) = ellipsoid_pose(cov, self.sigma)
            e.scale = Vector3(x=max(dx, 0.01), y=max(dy, 0.01), z=max(dz, 0.01))
            e.pose.orientation = Quaternion(x=qx, y=qy, z=qz, w=qw)
            e.color = ELLIPSOID
            lab = _marker("tracks_label", tid, Marker.TEXT_VIEW_FACING, stamp, frame_id)
            lab.pose.position = _pt(p[0], p[1], p[2] + 3.0 * self.radius_m)
            lab.scale = Vector3(x=0.0, y=0.0, z=2.0 * self.radius_m)
            lab.color = TRACK
            lab.text = f"{tid} p={prob:.2f}"
            tr = _marker("tracks_trail", tid, Marker.LINE_STRIP, stamp, frame_id)
            tr.scale = Vector3(x=0.3 * self.radius_m, y=0.0, z=0.0)
            tr.color = TRACK
            tr.points = [_pt(*q) for q in self._trails.get(tid, ())]
            out += [s, e, lab, tr]
        return out


class ReportLayer:
    """The last ``history`` radar reports (accepted / rejected) and RF fixes."""

    namespaces: tuple[str, ...] = ("radar_accepted", "radar_rejected", "rf_fixes")

    def __init__(self, history: int = 200, size_m: float = 5.0) -> None:
        self.size_m = size_m
        self.radar_ok: deque[tuple[float, float, float]] = deque(maxlen=history)
        self.radar_bad: deque[tuple[float, float, float]] = deque(maxlen=history)
        self.rf: deque[tuple[float, float, bool]] = deque(maxlen=history)

    def radar(self, z: Sequence[float] | np.ndarray, accepted: bool) -> None:
        (self.radar_ok if accepted else self.radar_bad).append(
            (float(z[0]), float(z[1]), float(z[2]))
        )

    def rf_fix(self, z: Sequence[float] | np.ndarray, used: bool) -> None:
        self.rf.append((float(z[0]), float(z[1]), used))

    def _list(self, ns: str, kind: int, pts: Iterable[tuple[float, float, float]],
              color: ColorRGBA, stamp: Time, frame_id: str) -> Marker:
        m = _marker(ns, 0, kind, stamp, frame_id)
        m.points = [_pt(*p) for p in pts]
        m.scale = Vector3(x=self.size_m, y=self.size_m, z=self.size_m)
        m.color = color
        return m

    def markers(self, stamp: Time, frame_id: str) -> list[Marker]:
        ok = self._list("radar_accepted", Marker.SPHERE_LIST, self.radar_ok, GREEN, stamp,
                        frame_id)
        bad = self._list("radar_rejected", Marker.SPHERE_LIST, self.radar_bad, RED, stamp,
                         frame_id)
        rf = self._list("rf_fixes", Marker.CUBE_LIST, ((e, n, 0.0) for e, n, _ in self.rf),
                        BLUE, stamp, frame_id)
        rf.colors = [BLUE if used else ORANGE for _, _, used in self.rf]
        rf.scale = Vector3(x=2 * self.size_m, y=2 * self.size_m, z=2 * self.size_m)
        return [ok, bad, rf]


class Visualization:
    """The ordered layers of ``fusion/markers``; :meth:`array` draws them all."""

    def __init__(self, frame_id: str, layers: Iterable[MarkerLayer] = ()) -> None:
        self.frame_id = frame_id
        self.layers: list[MarkerLayer] = []
        for layer in layers:
            self.add(layer)

    def add(self, layer: MarkerLayer) -> None:
        """Append a layer; its namespaces must be new."""
        taken = {ns for lay in self.layers for ns in lay.namespaces}
        clash = taken.intersection(layer.namespaces)
        if clash:
            raise ValueError(f"marker namespace(s) already used: {', '.join(sorted(clash))}")
        self.layers.append(layer)

    def array(self, stamp: Time) -> MarkerArray:
        out = MarkerArray()
        out.markers = [m for layer in self.layers for m in layer.markers(stamp, self.frame_id)]
        return out
