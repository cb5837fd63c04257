"""Work-precision reports (``flexmb bench``): error against wall time per simulated second.

For the cantilever B1 (SPEC §8), the spin-up maneuver (SPEC §7.6) and the Stewart platform twin
(SPEC §6.1), flexmb runs a sweep of Δt, elements per member, element order, integrator
(Newmark / generalized-α with several ρ∞) and Newton strategy (full / modified); each run's error
is measured against a converged reference (closed form where there is one, otherwise a fine run
stored under ``benchmarks/reference/``). Installed peers (Exudyn, MuJoCo, PyElastica) run in the
same process on the same cases. The flexmb runs go one after another in this process, or with
``--workers N`` / ``--scheduler ADDRESS`` as Dask tasks (``core.run_variants``; same errors, wall
times of concurrent runs — see ``cli``). Outputs: ``workprecision.csv``, one PNG per case and
``workprecision.md`` in ``docs/benchmarks/`` (or ``--out``).

Modules
-------
core      Variant (one fidelity), Row columns, the timed flexmb run, reference files, errors.
b1        B1 cantilever: sweep, reference (stored fine run + closed forms), peers.
spin_up   spin-up maneuver: sweep, stored fine reference.
stewart   Stewart twin: sweep, stored fine reference, peers.
report    CSV, matplotlib PNGs (imported lazily), markdown.
cli       ``flexmb bench`` flags and driver.
"""
