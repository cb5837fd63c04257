"""flexmb_core.numba_cache: a source change anywhere in the package drops the package's cached
kernels (numba itself only checks the file that defines a kernel, not the ones it calls)."""

from __future__ import annotations

from flexmb_core import numba_cache


def test_a_changed_source_drops_the_cached_kernels_and_an_unchanged_one_keeps_them(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    dirs = numba_cache._source_dirs()
    caches = numba_cache._cache_dirs(dirs, str(tmp_path))
    kernels = caches[0]
    kernels.mkdir(parents=True)
    (kernels / "fast.model_step-63.py311.nbi").write_text("index")
    (kernels / "fast.model_step-63.py311.1.nbc").write_text("code")
    other = tmp_path / "someone_else_0123"
    other.mkdir()
    (other / "x.f-1.py311.nbi").write_text("index")

    assert numba_cache.ensure_fresh()                 # no stamp yet: the sources are new to this cache
    assert not list(kernels.iterdir()) and (other / "x.f-1.py311.nbi").exists()
    (kernels / "fast.model_step-63.py311.nbi").write_text("index")
    assert not numba_cache.ensure_fresh()             # same sources: kept
    assert (kernels / "fast.model_step-63.py311.nbi").exists()

    stamp = next(tmp_path.glob("flexmb_sources_*"))
    stamp.write_text("digest of other sources")       # as after an edit of any kernel file
    assert numba_cache.ensure_fresh()
    assert not (kernels / "fast.model_step-63.py311.nbi").exists()
    assert stamp.read_text() == numba_cache._digest(dirs)


def test_cache_directories_follow_numbas_naming(tmp_path):
    import hashlib
    import os

    from numba.core.caching import UserProvidedCacheLocator

    d = numba_cache._source_dirs()[0]
    sub = UserProvidedCacheLocator.get_suitable_cache_subpath(str(d / "x.py"))
    assert numba_cache._cache_dirs([d], str(tmp_path)) == [tmp_path / sub]
    assert sub.endswith(hashlib.sha1(os.path.abspath(d).encode()).hexdigest())
