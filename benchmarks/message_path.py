"""Per-publication cost of the node's output path: build + serialize + publish + record.

    .venv/bin/python benchmarks/message_path.py [SCENE]      # default: the Stewart bars twin

Each output of one sample goes the node's way (``ros2_node.node.TwinNode._out``): built once by
:mod:`flexmb_io.messages`, serialized once by :mod:`flexmb_io.wire` (rosbags), the bytes published
by an rclpy publisher (no subscriber: DDS still writes the sample) and recorded by the
:class:`~flexmb_io.bag.recorder.BagRecorder`. Prints the median of 5 timed batches per type (µs).

Measured (2 shared cores, load 0.9–1.5; µs per publication, median; two interleaved runs of each,
"before" = the former path at 1b42782 — rclpy message filled and published, a dict built and
encoded by the hand-written CDR codec for the bag):

===================================  ===============  ===============
type (Stewart bars twin)             before           after
===================================  ===============  ===============
sensor_msgs/JointState               24.3, 23.3       21.8, 21.2
flexmb_msgs/TwinStatus               23.9, 23.6       16.8, 16.0
flexmb_msgs/ActuatorState            26.0, 24.1       21.1, 20.5
geometry_msgs/PoseStamped            20.0, 19.5       15.4, 14.9
rosgraph_msgs/Clock                  11.2, 11.1        9.9,  9.7
visualization_msgs/MarkerArray       306, 307         250, 229
  (Stewart shell twin)               413              270
===================================  ===============  ===============

Of "after", rosbags' serialization is most (JointState ≈ 13 µs, the bars' MarkerArray ≈ 115 µs); a
marker's constant parts are built once (``flexmb_io.messages._marker_constants``): built per marker,
the MarkerArray cost 640 µs.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_CACHE_DIR", str(ROOT / ".cache" / "numba"))


def main(scene: str = str(ROOT / "scenes" / "stewart_platform_bars.yaml")) -> int:
    import rclpy
    from rclpy.context import Context

    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene import load_scene
    from flexmb_io import messages as M
    from flexmb_io import topics as T
    from flexmb_io.bag.recorder import BagRecorder
    from flexmb_io.twin import RunnerOptions, TwinRunner
    from flexmb_io.wire import serialize
    from ros2_node.convert import message_class

    model = compile_scene(load_scene(scene, {"until": 1.0}))
    runner = TwinRunner(model, options=RunnerOptions())
    runner.start()
    s = runner.sample()
    shells, kinds, timing = runner.shells, runner.member_kinds, M.StatusTiming()
    cases = {T.JOINT_STATES: lambda: M.joint_state(s), T.STATUS: lambda: M.status(s, timing),
             T.ACTUATOR_STATES: lambda: M.actuator_state(s), T.PLATFORM_POSE: lambda: M.platform_pose(s, 0),
             T.CLOCK: lambda: M.clock(s.t), T.SHAPE: lambda: M.shape(s, kinds, shells)}
    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("message_path_bench", context=ctx)
    with tempfile.TemporaryDirectory() as tmp:
        rec = BagRecorder(Path(tmp) / "bag", scene_path=scene, scene_text=None, settings={})
        for topic, build in cases.items():
            pub = node.create_publisher(message_class(topic.type), topic.name, 10)
            rec.declare(topic.name, topic.type)

            def one(topic=topic, build=build, pub=pub):
                data = serialize(topic.type, build())
                pub.publish(data)
                rec.write_cdr(topic.name, topic.type, data, 1.0)

            n = 200 if topic is T.SHAPE else 3000
            for _ in range(n // 10):
                one()
            runs = []
            for _ in range(5):
                t0 = time.perf_counter()
                for _ in range(n):
                    one()
                runs.append((time.perf_counter() - t0) / n * 1e6)
            print(f"{topic.type:40s} {statistics.median(runs):8.1f} µs (median of 5 × {n})")
        rec.close()
    node.destroy_node()
    rclpy.shutdown(context=ctx)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(main(*sys.argv[1:2]))
