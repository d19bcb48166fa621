"""Analyses of the tracker on the benchmark's flights, from what only the twin knows
(``uav_fusion analyse``, :mod:`uav_fusion.commands.analyse`).

Each reads a benchmark definition's split from the flight cache, regenerates the twin in
memory to learn which object every radar track was following (:mod:`.labels`), and puts the
tracker's shortfalls down to causes:

* :mod:`.misses`: why an epoch where the radar sees the UAV has no track or a gross error
  (single-UAV), or why a UAV-epoch has no track (multi-UAV);
* :mod:`.oracle`: the same filter with association from the twin's labels, scored beside the
  tracker (single- and multi-UAV);
* :mod:`.false_tracks`: what the multi-UAV tracker's false tracks follow;
* :mod:`.locks`: what the single-UAV tracker's confirmed track follows, and for how long.

Each analysis builds and drives its estimator in one small function (``_track_*``,
``_run_*``, ``_follow``); everything else is scoring and counting.
"""
