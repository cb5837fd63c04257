"""The ROS interface is a contract: every topic and node parameter is documented in the README,
and the topic table matches flexmb_io.topics (names and types)."""

from pathlib import Path

from flexmb_io import topics as T
from ros2_node.params import SPECS, NodeParams, check

import pytest
from flexmb_core.errors import FlexmbError

README = (Path(__file__).resolve().parents[2] / "README.md").read_text()


@pytest.mark.parametrize("topic", T.ALL, ids=lambda t: t.name)
def test_every_topic_is_documented_with_its_type(topic):
    row = [line for line in README.splitlines() if line.startswith(f"| `{topic.resolved()}` |")]
    assert row, f"README has no row for {topic.resolved()}"
    assert f"`{topic.type}`" in row[0] and f"| {topic.direction} |" in row[0]


@pytest.mark.parametrize("spec", SPECS, ids=lambda s: s.name)
def test_every_parameter_is_documented(spec):
    assert f"`{spec.name}`" in README


def test_parameter_table_and_dataclass_agree():
    defaults = NodeParams()
    for spec in SPECS:
        assert getattr(defaults, spec.name) == spec.default, spec.name


@pytest.mark.parametrize("name,value,expect", [
    ("publish_rate", -5.0, "publish_rate"), ("mode", "fast", "realtime"), ("qos_depth", 1.5, "integer"),
    ("command_timeout", float("nan"), "finite"), ("publish_clock", "yes", "true or false"),
])
def test_bad_parameters_are_named(name, value, expect):
    with pytest.raises(FlexmbError, match=expect):
        check(name, value)
