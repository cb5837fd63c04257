"""Numba's on-disk cache, kept in step with the sources of the whole package.

Numba validates a cached kernel against the timestamp and size of the file that *defines* it, not
of the files whose functions it calls: after an edit of ``kernels/frame3d.py`` the cached
``integrators/fast.model_step`` still holds the old frame kernel inlined (measured: material
damping silently vanished from the numba step). So the package keeps one digest of all its
sources next to the cache; when it differs, every cached kernel of this package is removed and
recompiled on first use. Other projects' entries in a shared ``NUMBA_CACHE_DIR`` are left alone.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

_ROOT = Path(__file__).resolve().parent


def _source_dirs() -> list[Path]:
    return sorted({p.parent for p in _ROOT.rglob("*.py")})


def _digest(dirs: list[Path]) -> str:
    h = hashlib.sha256()
    for d in dirs:
        for p in sorted(d.glob("*.py")):
            h.update(str(p.relative_to(_ROOT)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def _cache_dirs(dirs: list[Path], cache_root: str) -> list[Path]:
    """Where numba keeps the kernels of each source directory (its own naming, see
    ``numba.core.caching._CacheLocator.get_suitable_cache_subpath``)."""
    if not cache_root:
        return [d / "__pycache__" for d in dirs]
    out = []
    for d in dirs:
        path = os.path.abspath(d)
        out.append(Path(cache_root) / f"{os.path.basename(path)}_{hashlib.sha1(path.encode()).hexdigest()}")
    return out


def ensure_fresh() -> bool:
    """Drop this package's cached kernels when any of its sources changed since they were cached.
    Returns True when something was dropped. Never raises (a read-only or missing cache is left
    to numba, which then compiles in memory)."""
    try:
        root = os.environ.get("NUMBA_CACHE_DIR", "")
        dirs = _source_dirs()
        stamp = (Path(root) if root else _ROOT / "__pycache__") / f"flexmb_sources_{hashlib.sha1(str(_ROOT).encode()).hexdigest()[:12]}"
        digest = _digest(dirs)
        if stamp.is_file() and stamp.read_text() == digest:
            return False
        dropped = False
        for c in _cache_dirs(dirs, root):
            if c.is_dir():
                for f in list(c.glob("*.nbi")) + list(c.glob("*.nbc")):
                    f.unlink(missing_ok=True)
                    dropped = True
        stamp.parent.mkdir(parents=True, exist_ok=True)
        tmp = stamp.with_suffix(f".{os.getpid()}")
        tmp.write_text(digest)
        tmp.replace(stamp)
        return dropped
    except OSError:
        return False
