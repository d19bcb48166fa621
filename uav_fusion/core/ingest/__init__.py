"""Live sensor input without ROS: transports (TCP client, UDP, a followed file), line framing,
the per-line decoders of the three Dataset-28 formats with their bad-line accounting, the
per-source monitor (rate, age, latency, clock offset), and the sensor emulator.

The stream nodes (``radar_stream``, ``rf_stream``, ``truth_stream``) are thin wrappers around
:class:`uav_fusion.core.ingest.stream.Ingest`; see ``docs/graph.md``, "Live ingest".
"""
