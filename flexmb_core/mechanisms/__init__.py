"""Mechanism definitions and their commanded motions (pure numpy, no solver dependency)."""

from flexmb_core.mechanisms.stewart import (
    StewartGeometry,
    StewartLayout,
    appendix_leg_lengths,
    appendix_platform_outputs,
    appendix_pose,
    appendix_vertex_displacements,
    appendix_vertex_displacements_literal,
    appendix_vertex_positions,
    blend_quintic,
    default_leg_names,
    read_command_table,
    write_command_table,
)

__all__ = [
    "StewartGeometry",
    "StewartLayout",
    "appendix_leg_lengths",
    "appendix_platform_outputs",
    "appendix_pose",
    "appendix_vertex_displacements",
    "appendix_vertex_displacements_literal",
    "appendix_vertex_positions",
    "blend_quintic",
    "default_leg_names",
    "read_command_table",
    "write_command_table",
]
