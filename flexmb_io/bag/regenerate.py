"""``flexmb bag regenerate``: re-record the reference bags listed in ``bags/manifest.yaml``.

Each manifest entry names the bag (its directory under ``bags/``) and the exact ``flexmb run``
command that produced it, run from the repository root (the manifest directory's parent). The
new recording is made in a temporary directory, replayed (it must be bit-identical to itself), and
only then replaces the old one; the entry's ``scene_sha256``, ``flexmb_version``, ``date``,
``messages``, ``bytes`` and ``t_end_s`` are rewritten. Tolerances and descriptions are kept.
"""

from __future__ import annotations

import datetime
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

from flexmb_core.errors import FlexmbError

from .replay_many import MANIFEST, manifest_bags
HEADER = """\
# Reference recordings of flexmb (issue 6). tests/bag/test_replay_bags.py replays every bag listed
# here with `flexmb replay BAG --tolerance <tolerances>` and requires exit code 0; a change of the
# solver's results shows up as a field beyond tolerance. After an INTENDED change of results,
# re-record with `bags/regenerate.sh` (or `flexmb bag regenerate [--only NAME]`) and commit the
# bags with this file. Each entry: the command that produced the bag (run from the repository
# root), the sha256 of the scene text embedded in the bag, the flexmb version, the tolerances the
# replay uses (defaults: flexmb replay --help), the date and the bag's size.
"""


def load_manifest(bags_dir: Path) -> dict:
    """The ``bags`` mapping of ``bags_dir/manifest.yaml`` (name → entry).

    Raises
    ------
    FlexmbError
        When the file is missing or has no ``bags`` mapping, or an entry lacks ``command``.
    """
    path = Path(bags_dir) / MANIFEST
    if not path.is_file():
        raise FlexmbError(f"{path}: no manifest (expected {MANIFEST} listing the reference bags)")
    bags = manifest_bags(path)
    for name, entry in bags.items():
        if not isinstance(entry, dict) or not isinstance(entry.get("command"), str):
            raise FlexmbError(f"{path}:bags.{name}: expected a mapping with a 'command' string")
    return bags


def save_manifest(bags_dir: Path, bags: dict) -> None:
    text = HEADER + yaml.safe_dump({"bags": bags}, sort_keys=False, allow_unicode=True, width=110)
    (Path(bags_dir) / MANIFEST).write_text(text, encoding="utf-8")


def _command(name: str, entry: dict, out: Path) -> list[str]:
    argv = shlex.split(entry["command"])
    if argv[:2] != ["flexmb", "run"] or "--mcap" not in argv:
        raise FlexmbError(f"{MANIFEST}:bags.{name}.command: expected 'flexmb run SCENE ... --mcap bags/{name}', "
                          f"got {entry['command']!r}")
    k = argv.index("--mcap")
    argv[k + 1] = str(out)
    return [sys.executable, "-m", "flexmb.cli"] + argv[1:]


def regenerate(bags_dir: Path, only: list[str] | None = None) -> int:
    """Re-record the manifest's bags (all, or ``only`` these names); returns an exit code."""
    from .reader import BagReader
    from .replay import replay

    bags_dir = Path(bags_dir).resolve()
    root = bags_dir.parent
    bags = load_manifest(bags_dir)
    unknown = sorted(set(only or ()) - set(bags))
    if unknown:
        raise FlexmbError(f"--only {unknown}: not in {bags_dir / MANIFEST} (has {sorted(bags)})")
    env = dict(os.environ)
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    for name, entry in bags.items():
        if only and name not in only:
            continue
        with tempfile.TemporaryDirectory(prefix=f"flexmb-{name}-") as tmp:
            out = Path(tmp) / name
            argv = _command(name, entry, out)
            print(f"{name}: {entry['command']}", flush=True)
            proc = subprocess.run(argv, cwd=root, env=env)
            if proc.returncode != 0:
                print(f"{name}: the run failed (exit {proc.returncode}); the old bag is kept", file=sys.stderr)
                return 1 if proc.returncode == 1 else 2      # 1: its command is bad input (it said why)
            report = replay(out, tolerances=entry.get("tolerances") or {})
            if not report.ok or not all(f.identical for f in report.fields):
                print(report.format(), file=sys.stderr)
                print(f"{name}: the new recording does not replay bit-identically; the old bag is kept",
                      file=sys.stderr)
                return 3
            r = BagReader(out)
            dest = bags_dir / name
            if dest.exists():
                shutil.rmtree(dest)
            shutil.move(str(out), str(dest))        # the file is already named <name>_0.mcap
        first, last = r.time_range_ns()
        entry.update(scene_sha256=r.settings().get("scene_sha256", ""), flexmb_version=r.settings().get("version", ""),
                     date=datetime.date.today().isoformat(), messages=len(r.messages_raw),
                     bytes=sum(f.stat().st_size for f in dest.iterdir()), t_end_s=round(last * 1e-9, 9))
        save_manifest(bags_dir, bags)               # after each bag: manifest and bags stay in step
        print(f"{name}: {entry['messages']} messages, {entry['bytes'] / 1e6:.2f} MB, replay bit-identical", flush=True)
    return 0

