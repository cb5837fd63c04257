"""Recording defaults shared by the recorder, ``flexmb run --mcap`` and the command line (no imports)."""

DEFAULT_RECORD_RATE = 100.0     # Hz of simulated time: outputs of ``flexmb run --mcap``
MAX_SHAPE_RATE = 20.0           # Hz: ``~/shape`` MarkerArrays are large
CHUNK_SECONDS = 0.25            # s of simulated time per MCAP chunk: what a SIGKILL may lose
CHUNK_MESSAGES = 5000           # messages per chunk at most
