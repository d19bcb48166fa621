"""Scoring against truth: Table II, fixed-rate errors, GOSPA, sensor calibration, reports."""
