"""Fixtures of the recording tests: one short recorded run."""

from __future__ import annotations

from pathlib import Path

import pytest
from bag_helpers import STEWART_BARS, flexmb

@pytest.fixture(scope="session")
def stewart_bag(tmp_path_factory) -> Path:
    """``flexmb run scenes/stewart_platform_bars.yaml --until 0.5 --mcap BAG`` (pose, tf, 6 actuators)."""
    out = tmp_path_factory.mktemp("rec") / "stewart_short"
    p = flexmb("run", STEWART_BARS, "--until", "0.5", "--quiet", "--mcap", out)
    assert p.returncode == 0, p.stderr
    return out
