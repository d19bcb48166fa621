"""``diagnostic_msgs/DiagnosticStatus`` entries as the fusion and evaluator nodes publish them."""

from __future__ import annotations

from collections.abc import Iterable

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

HARDWARE_ID = "uav_fusion"


def make_status(
    name: str, message: str, values: Iterable[tuple[str, str]], *, warn: bool = False
) -> DiagnosticStatus:
    """One status, level WARN when ``warn`` else OK, holding ``values`` as KeyValue pairs."""
    st = DiagnosticStatus()
    st.name = name
    st.hardware_id = HARDWARE_ID
    st.level = DiagnosticStatus.WARN if warn else DiagnosticStatus.OK
    st.message = message
    st.values = [KeyValue(key=k, value=v) for k, v in values]
    return st
