"""Derive the 1-element frame-leg twins from scenes/stewart_platform.yaml (1 cubic element per leg):
scenes/stewart_platform_1el.yaml (its frame platform) and scenes/stewart_platform_1el_truss.yaml
(the bar-leg twin's truss platform)."""
from pathlib import Path

src = Path("scenes/stewart_platform.yaml").read_text()
HEAD_1EL = """# The Stewart twin with flexible frame legs at the lowest mesh: scenes/stewart_platform.yaml with
# ONE cubic frame element per leg instead of four (leg bending and the first leg modes kept). Offline
# it runs at RTF ≈ 11 against ≈ 5 for 4 elements, 2.4e-10 m from the converged reference
# (docs/benchmarks/stewart.md). With the platform's edges as bars instead of frames,
# scenes/stewart_platform_1el_truss.yaml is ≈ 1.6× faster again. Everything else is identical;
# regenerate with `python scenes/tools/make_stewart_1el.py` after editing stewart_platform.yaml.
#
"""
HEAD_TRUSS = """# The flexible-leg Stewart twin at real-time cost: flexible frame legs (ONE cubic element each, as
# scenes/stewart_platform_1el.yaml) on the truss platform of scenes/stewart_platform_bars.yaml (three
# pin-jointed steel tubes as bars: a rigid triangle for the legs' ball joints, with the tubes' mass and
# inertia, as a rigid-body platform). The legs keep their bending and their first modes; the platform
# edges lose only their own bending, which moves the platform by ~1e-10 m (docs/benchmarks/stewart.md,
# against the converged reference with flexible edges). Offline it runs at RTF ≈ 18 (≈ 1.6× the
# frame platform, ≈ 1.9× Exudyn's ANCF legs on a rigid platform in the same run). Everything else is
# identical; regenerate with `python scenes/tools/make_stewart_1el.py` after editing stewart_platform.yaml.
#
"""
LEG_4 = "elements: 4, order: 3, material: steel, section: leg"
EDGE_FRAME = "edge_ab: &edge {kind: frame, from: A, to: B, elements: 2, order: 3, material: steel, section: edge}"
EDGE_TRUSS = "edge_ab: &edge {kind: truss, from: A, to: B, material: steel, section: edge}"


def one_element(name: str, what: str) -> str:
    out = src.replace("name: stewart_platform\n", f"name: {name}\n", 1)
    out = out.replace("description: Seed-paper Stewart platform, flexible actuator legs,",
                      f"description: Seed-paper Stewart platform, flexible actuator legs ({what}),", 1)
    assert out.count(LEG_4) == 1, out.count(LEG_4)
    out = out.replace("(frame variant, 4 cubic elements each)", "(frame variant, 1 cubic element each)", 1)
    return out.replace(LEG_4, LEG_4.replace("elements: 4", "elements: 1"))


Path("scenes/stewart_platform_1el.yaml").write_text(HEAD_1EL + one_element("stewart_platform_1el",
                                                                            "1 cubic element each"))
truss = one_element("stewart_platform_1el_truss", "1 cubic element each, truss platform")
assert truss.count(EDGE_FRAME) == 1, truss.count(EDGE_FRAME)
truss = truss.replace(EDGE_FRAME, EDGE_TRUSS)
PLATFORM = "# Platform: three steel tube edges (pin-jointed, which is rigid for a triangle) + 10 kg payload."
truss = truss.replace(PLATFORM, PLATFORM.replace("tube edges (", "tube edges as bars ("))
Path("scenes/stewart_platform_1el_truss.yaml").write_text(HEAD_TRUSS + truss)
print("ok")
