"""Compile a scene into a read-only :class:`Model`; ``State`` and ``Workspace`` for the loop."""
