"""Entity paths of a twin recording and the default rerun blueprint (a 3D view and the plots).

The paths are the contract the tests and the blueprint share: change them here only.
"""

from __future__ import annotations

import numpy as np

from .layout import TwinLayout

TIMELINE = "sim_time"

WORLD = "world"
AXES = "world/axes"
SUPPORTS = "world/supports"
MEMBERS = "world/members"            # + /<member name> (a name "a/b" nests as a/b)
SHELLS = "world/shells"              # + /<shell name>: Mesh3D (triangles static, vertex positions per time)
PLATFORMS = "world/platforms"        # + /<platform>/frame (pose), /mesh and /outline (world coordinates)

ACT_LENGTH = "plots/actuators/length"
ACT_COMMAND = "plots/actuators/command"
ACT_FORCE = "plots/actuators/force"
ACT_VELOCITY = "plots/actuators/velocity"
ACT_INPUT = "plots/actuators/input"  # commands as received (recordings with input topics)
JOINT_ANGLE = "plots/joints/angle"
JOINT_RATE = "plots/joints/velocity"
NEWTON = "plots/solver/newton_iterations"
RESIDUAL = "plots/solver/residual"
STEP_WALL = "plots/solver/step_wall_time"
RTF = "plots/solver/real_time_factor"
ENERGY = "plots/energy"              # instances: kinetic, strain, total
SOLVER_LOG = "log/solver"

ENERGY_NAMES = ("kinetic", "strain", "total")


def eye_pose(layout: TwinLayout) -> tuple[np.ndarray, np.ndarray] | None:
    """Camera position and target (m): the mechanism seen from the front right, a little above,
    about 2 sizes away (None when its bounds are unknown)."""
    if layout.bounds is None:
        return None
    centre = layout.bounds.mean(axis=0)
    return centre + layout.size() * np.array([1.0, -1.3, 0.55]), centre


def eye_controls(layout: TwinLayout):
    """An orbital camera at :func:`eye_pose`, z up (None: rerun frames the scene itself)."""
    import rerun.blueprint as rrb

    pose = eye_pose(layout)
    if pose is None:
        return None
    return rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=pose[0], look_target=pose[1],
                             eye_up=[0.0, 0.0, 1.0])


def build_blueprint(layout: TwinLayout, *, snapshot: bool = False):
    """The default layout: the 3D mechanism on the left; on the right actuator lengths (and
    velocities, joint angles in tabs), axial forces, solver health and energies.

    ``snapshot`` collapses the side and time panels, for a PNG of the views alone.
    """
    import rerun.blueprint as rrb

    # one legend (forces) names the actuator colours for all plots; single series need none
    quiet = rrb.PlotLegend(visible=False)
    lengths = rrb.TimeSeriesView(name="actuator lengths (m)", origin="plots/actuators",
                                 contents=[f"+ {ACT_LENGTH}", f"+ {ACT_COMMAND}", f"+ {ACT_INPUT}"],
                                 plot_legend=quiet)
    tabs = [lengths, rrb.TimeSeriesView(name="actuator velocities (m/s)", origin=ACT_VELOCITY, plot_legend=quiet)]
    if layout.joint_names:
        tabs.append(rrb.TimeSeriesView(name="joint angles (rad)", origin=JOINT_ANGLE))
    plots = rrb.Vertical(
        rrb.Tabs(*tabs, active_tab=0) if len(tabs) > 1 else lengths,
        rrb.TimeSeriesView(name="actuator axial forces (N)", origin=ACT_FORCE,
                           plot_legend=rrb.PlotLegend(corner="LeftTop")),
        rrb.Horizontal(
            rrb.TimeSeriesView(name="Newton iterations", origin=NEWTON, plot_legend=quiet),
            rrb.TimeSeriesView(name="relative residual", origin=RESIDUAL, plot_legend=quiet),
            rrb.TimeSeriesView(name="step wall time (s)", origin=STEP_WALL, plot_legend=quiet),
            rrb.TimeSeriesView(name="real-time factor", origin=RTF, plot_legend=quiet),
        ),
        rrb.TimeSeriesView(name="energies (J)", origin=ENERGY),
    )
    view3d = rrb.Spatial3DView(name=f"{layout.name}", origin=WORLD, eye_controls=eye_controls(layout))
    panel = "collapsed" if snapshot else "expanded"
    return rrb.Blueprint(
        rrb.Horizontal(view3d, plots, column_shares=[3, 2]),
        rrb.BlueprintPanel(state="collapsed" if snapshot else "expanded"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE, state=panel),
        auto_views=False,
    )
