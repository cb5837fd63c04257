"""The one mutable object of a run: :class:`StepData` (MuJoCo's ``mjData`` to the ``Model``).

Everything a dynamic step reads from one step and writes for the next lives in one float buffer:
the time and the unknowns with their rates (the :class:`~flexmb_core.model.workspace.State`), the
actuator stretches with their history (the backward difference of the stretch rate reads
λ_{n−1}), the Lagrange multipliers, the servos, the held tangent's bookkeeping and the step
guard's energy ledger. Named items are views of that buffer, so

* :meth:`StepData.copy` and :meth:`StepData.assign` act on the whole run state at once — a
  rollback (a rejected step, a fault that stops the twin) restores the stretch history and the
  ledger with the unknowns, instead of each owner invalidating its own part;
* the numba step takes the buffer and its layout table as two arguments instead of eleven.

Not in the buffer: the model's constants and every scratch array (the packs of
:mod:`flexmb_core.integrators.packs`, the :class:`~flexmb_core.model.workspace.Workspace`), which
a step overwrites before it reads them, and the held tangent's LU factors, a cache of the
tangent at some recent state. ``tan[3]`` counts the factorizations and never rolls back in the
data that owns the factors: an :meth:`~StepData.assign` from a copy taken before the last
factorization marks the tangent as not held, so the next step refactors instead of reusing
factors that belong to a state the run has left.
"""

from __future__ import annotations

import math

import numpy as np

from .model import Model
from .workspace import State

# Items of the buffer (rows of the layout table, [offset, d0, d1, d2, d3, size] as the packs'
# rows, so that the packs' view helpers read them).
(D_CLOCK, D_Q, D_V, D_A, D_ATIL, D_LAM, D_LAMRATE, D_LAMHIST, D_LAMCAND, D_MULT, D_SERVOX, D_SERVOV, D_TAN,
 D_LED, D_GVEC, D_REACT, D_QREF, N_DATA) = range(18)
# Slots of the clock item: t (s); the stretch history's λ_{n−1} time and the time of the state it
# belongs to (NaN: no history, the next rate is a first-order difference).
C_T, C_T_PREV, C_T_HIST = range(3)
# Slots of the held tangent item: held (0/1), its coefficient c_a + c_m c_v, age in steps,
# factorizations so far.
T_HELD, T_COEF, T_AGE, T_COUNT = range(4)


def drive_dof_ids(model: Model) -> np.ndarray:
    """Sorted DOF indices that driven supports prescribe (positions and vectors), int64."""
    d = model.drives
    ids = [] if d is None else [d.y_ids.ravel(), d.v_ids.ravel()]
    return np.unique(np.concatenate(ids)).astype(np.int64) if ids else np.zeros(0, dtype=np.int64)


def data_shapes(model: Model) -> list[tuple[int, ...]]:
    """Shapes of the items ``D_*`` of ``model``'s step data, in item order."""
    n, na, nm = model.ndof, model.actuators.l0.size, model.n_multipliers
    servo = model.actuators.servo
    ns = 0 if servo is None else servo.size
    nd = drive_dof_ids(model).size
    # q_ref: the unknowns the held tangent was formed at, for models whose held tangent follows
    # their shells' rotation (kernels/corotation.py)
    return [(4,), (n,), (n,), (n,), (n,), (na,), (na,), (na,), (na,), (nm,), (ns,), (ns,), (4,), (5,), (6, n),
            (2, nd), (n if model.shells else 0,)]


class BoundState(State):
    """A :class:`State` whose time and arrays are views of a :class:`StepData` buffer.

    It is the state everyone reads (``sim.state``); :meth:`State.copy` of it is a plain,
    independent :class:`State`, :meth:`State.assign` copies into the buffer."""

    _clock: np.ndarray

    @property
    def t(self) -> float:       # type: ignore[override]
        return float(self._clock[C_T])

    @t.setter
    def t(self, value: float) -> None:
        self._clock[C_T] = value


class StepData:
    """Everything a run's steps carry from one step to the next, in one buffer (see the module).

    Parameters
    ----------
    model : Model — sizes the items; the state starts at rest in the reference configuration
        (:meth:`State.at_rest`), with no stretch history, no held tangent and no ledger.
    owns_factors : bool — this data goes with the integrator's LU factors (the simulator's own;
        copies do not), so :meth:`assign` keeps ``tan``'s factorization count and drops a tangent
        factored after the copy it restores.

    Attributes
    ----------
    buf : (size,) float64 — the buffer; lay : (N_DATA, 6) int64 — its layout table (read-only).
    state : BoundState — time, unknowns and rates, stretches, multipliers, servos (views).
    clock : (4,) — [t (s), t_prev (s), t_hist (s), unused].
    lam_hist, lam_cand : (na,) — λ_{n−1} and the candidate λ_n of the step under way.
    tan : (4,) — held tangent [held, coefficient, age, factorizations].
    q_ref : (ndof,) or (0,) — the unknowns the held tangent was formed at (models with shells:
        their rotation since then is the held tangent's, :mod:`flexmb_core.kernels.corotation`).
    led : (5,) — the guard's ledger [il, ir, t, K + U, candidate K + U]; gvec (6, ndof) and
        react (2, nd) its rows (:class:`~flexmb_core.solvers.guard.StepGuard`).
    """

    def __init__(self, model: Model, *, owns_factors: bool = True, _buf: np.ndarray | None = None,
                 _lay: np.ndarray | None = None):
        if _lay is None:
            shapes = data_shapes(model)
            lay = np.zeros((N_DATA, 6), dtype=np.int64)
            offset = 0
            for item, shape in enumerate(shapes):
                size = int(np.prod(shape))
                dims = list(shape) + [1] * (4 - len(shape))
                lay[item] = [offset, *dims, size]
                offset += size
            lay.setflags(write=False)
            _lay = lay
        self.model = model
        self.lay = _lay
        self.owns_factors = owns_factors
        self.buf = np.zeros(int(_lay[-1, 0] + _lay[-1, 5])) if _buf is None else _buf
        self.clock = self.item(D_CLOCK)
        self.lam_hist = self.item(D_LAMHIST)
        self.lam_cand = self.item(D_LAMCAND)
        self.tan = self.item(D_TAN)
        self.q_ref = self.item(D_QREF)
        self.led = self.item(D_LED)
        self.gvec = self.item(D_GVEC)
        self.react = self.item(D_REACT)
        st = BoundState.__new__(BoundState)
        st._clock = self.clock
        st.q, st.v, st.a, st.atil = (self.item(i) for i in (D_Q, D_V, D_A, D_ATIL))
        st.lam, st.lam_rate, st.mult = self.item(D_LAM), self.item(D_LAMRATE), self.item(D_MULT)
        st.servo_x, st.servo_v = self.item(D_SERVOX), self.item(D_SERVOV)
        self.state = st
        if _buf is None:
            self.state.assign(State.at_rest(model))
            self.clock[C_T_PREV] = 0.0
            self.clock[C_T_HIST] = math.nan
            self.led[:] = (0.0, 0.0, math.nan, 0.0, 0.0)

    def item(self, item: int) -> np.ndarray:
        """The writable view of item ``D_*`` in its shape."""
        o, d0, d1, size = self.lay[item, 0], self.lay[item, 1], self.lay[item, 2], self.lay[item, 5]
        flat = self.buf[o:o + size]
        return flat.reshape((d0, d1)) if item in (D_GVEC, D_REACT) else flat

    def copy(self) -> "StepData":
        """An independent copy (one buffer copy); it owns no factors."""
        return StepData(self.model, owns_factors=False, _buf=self.buf.copy(), _lay=self.lay)

    def assign(self, other: "StepData") -> None:
        """Copy ``other``'s buffer into this one (no allocation): the whole run state at once.

        Data that owns the factors keeps its factorization count, and holds no tangent when
        ``other`` was taken before the last factorization (see the module)."""
        if not self.owns_factors:
            self.buf[:] = other.buf
            return
        count = self.tan[T_COUNT]
        self.buf[:] = other.buf
        if other.tan[T_COUNT] != count:
            self.tan[T_HELD] = 0.0
        self.tan[T_COUNT] = count
