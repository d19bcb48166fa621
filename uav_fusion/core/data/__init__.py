"""Readers for the AERPAW Dataset-28 flight files (Keysight RF CSV, Fortem radar JSON Lines,
vehicle truth log), returning the typed records of :mod:`uav_fusion.core.records` on one UTC
timeline with ENU coordinates from the :class:`~uav_fusion.core.site.Site`.

Public API::

    read_rf_csv(path, site, *, strict=False) -> (list[RfAttempt], LoadReport)
    read_radar_jsonl(path, site, *, strict=False) -> (list[RadarFrame], LoadReport)
    read_truth(path, site, *, strict=False) -> (list[TruthFix], LoadReport)
    load_flight(folder, site=None, *, rf_file="AADM.csv", radar_glob="radar_data_*.json",
                truth_glob="*vehicleOut.txt", strict=False) -> Flight

Every reader has two modes. Lenient (default): a bad row is skipped and counted by reason in
``LoadReport.skipped``; reading continues. Strict: the first problem raises
:class:`~uav_fusion.core.errors.DataError` naming the file, the 1-based line and what was
wrong. ``docs/dataset.md`` describes the formats and policies.

The machinery the three readers share lives in :mod:`uav_fusion.core.data._source`.
"""

from __future__ import annotations

from uav_fusion.core.data._source import fmt_utc
from uav_fusion.core.data.flight import load_flight
from uav_fusion.core.data.radar import read_radar_jsonl
from uav_fusion.core.data.rf import read_rf_csv
from uav_fusion.core.data.truth import read_truth

__all__ = ["fmt_utc", "load_flight", "read_radar_jsonl", "read_rf_csv", "read_truth"]
