"""Peer codes run on flexmb's benchmarks as baselines (optional; each peer is imported lazily).

Each module offers ``available() -> bool`` and a ``run_*`` function returning a plain dict;
the caller skips a peer whose package is not installed (``pip install -e .[peers]``).
"""
