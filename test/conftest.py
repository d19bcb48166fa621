"""Test-session environment: DDS discovery on localhost only, a random domain per session.

This runs before any test module imports rclpy, so every rclpy context in the session
(and every child process, which inherits the environment) stays on this machine.
"""

from __future__ import annotations

import os
import random
import tempfile
from collections.abc import Iterator
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:  # rclpy is imported only once the environment below is set
    from rclpy.context import Context

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
if "PYTEST_XDIST_WORKER" not in os.environ:
    os.environ["ROS_DOMAIN_ID"] = str(random.SystemRandom().randint(1, 100))
os.environ.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="uav_fusion_roslog_"))


@pytest.fixture()
def ctx() -> Iterator[Context]:
    """A fresh rclpy context for one test, shut down afterwards."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    yield context
    rclpy.shutdown(context=context)
