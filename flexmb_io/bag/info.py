"""``flexmb bag info BAG``: what a recording holds, read record by record (tolerates truncation)."""

from __future__ import annotations

from pathlib import Path

from . import rosbag2
from .reader import BagReader


def bag_info(path) -> dict:
    """A summary of the bag at ``path``: file, completeness, topics with types and counts, time
    span (s), scene, the ``flexmb`` settings, and whether ``metadata.yaml`` agrees with the file."""
    r = BagReader(path)
    first, last = r.time_range_ns()
    counts = r.counts()
    types = r.topics()
    out = {"path": str(path), "file": str(r.file), "bytes": r.file.stat().st_size, "profile": r.profile,
           "complete": not r.truncated, "problem": r.problem, "valid_bytes": r.valid_bytes, "chunks": r.chunks,
           "messages": sum(counts.values()), "t_first_s": first * 1e-9, "t_last_s": last * 1e-9,
           "topics": {t: {"type": types.get(t, ""), "count": counts.get(t, 0)} for t in sorted(types)},
           "attachments": sorted(r.attachments), "settings": r.settings()}
    meta_dir = Path(path) if Path(path).is_dir() else None
    if meta_dir is not None and (meta_dir / rosbag2.METADATA_FILE).is_file():
        try:
            meta = rosbag2.read(meta_dir)
            # a topic declared up front (the node declares every topic it may record) and never
            # written is listed with 0 messages but has none in the file: compare the written ones
            listed = {t["topic_metadata"]["name"]: int(t["message_count"])
                      for t in meta.get("topics_with_message_count", []) if int(t["message_count"])}
            total = int(meta.get("message_count", 0))
            out["metadata_yaml"] = {"message_count": total,
                                    "agrees": listed == {t: c for t, c in counts.items() if c}
                                    and total == sum(counts.values())}
        except (ValueError, KeyError, TypeError) as exc:
            out["metadata_yaml"] = {"error": str(exc)}
    return out


def format_info(info: dict) -> str:
    s = info["settings"]
    lines = [f"bag {info['path']}  ({info['file']}, {info['bytes'] / 1e6:.3f} MB, {info['chunks']} chunks)",
             "  state      " + ("complete" if info["complete"] else
                                 f"CUT SHORT: {info['problem']} — `flexmb bag recover IN OUT` keeps the "
                                 f"{info['valid_bytes']} good bytes"),
             f"  messages   {info['messages']}, t = {info['t_first_s']:.6g} … {info['t_last_s']:.6g} s (simulated)",
             f"  scene      {s.get('scene', '?')} (sha256 {s.get('scene_sha256', '?')[:16]}…, from {s.get('scene_file', '?')})",
             f"  recorded   by {s.get('source', '?')}, flexmb {s.get('version', '?')}, {s.get('created', '?')}; "
             f"Δt = {s.get('dt', '?')} s, {s.get('integrator', '?')}"]
    meta = info.get("metadata_yaml")
    if meta is not None:
        lines.append("  metadata   " + (f"error: {meta['error']}" if "error" in meta else
                                        f"{meta['message_count']} messages, "
                                        + ("agrees with the file" if meta["agrees"] else
                                           "DIFFERS from the file (written before the last chunks)")))
    w = max([len(t) for t in info["topics"]] + [5])
    for t, d in info["topics"].items():
        lines.append(f"  {t:{w}s}  {d['count']:7d}  {d['type']}")
    return "\n".join(lines)
