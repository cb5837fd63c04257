"""Linearized modal analysis about a configuration: ``K(q) φ = ω² M φ`` on the free DOFs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from .errors import FlexmbError
from .model.assembly import assemble, update_load_scales
from .model.model import Model
from .model.workspace import Workspace


@dataclass(frozen=True)
class Modes:
    """Natural frequencies (rad/s, ascending) and mass-normalised mode shapes ``(ndof, n)``
    (prescribed DOFs zero)."""

    omega: np.ndarray
    shapes: np.ndarray

    @property
    def hertz(self) -> np.ndarray:
        return self.omega / (2.0 * np.pi)


def natural_modes(model: Model, q: np.ndarray | None = None, lam: np.ndarray | None = None,
                  n_modes: int | None = None, t: float = 0.0) -> Modes:
    """Dense generalized eigen-solve of the tangent at ``q`` (default: the reference state).

    Includes the load stiffness of configuration-dependent loads at time ``t``. Meant for
    verification and model inspection (n ≲ 3000 free DOFs), not for the time loop.
    """
    if model.n_multipliers:
        raise FlexmbError("modal analysis of models with rigid corners (multipliers) is not supported yet")
    ws = Workspace(model)
    # a writable copy: the frozen model.q0 would compile a read-only specialization of the kernels
    q = np.array(model.q0 if q is None else q, dtype=float)
    lam = np.ones(model.actuators.l0.size) if lam is None else lam
    update_load_scales(model, ws, t)
    assemble(model, ws, q, lam, True)
    shape = (model.nfree, model.nfree)
    k = sp.csr_matrix((ws.kdata, model.indices, model.indptr), shape=shape).toarray()
    m = sp.csr_matrix((model.mass_kdata, model.indices, model.indptr), shape=shape).toarray()
    k = 0.5 * (k + k.T)
    hi = None if n_modes is None else min(n_modes, model.nfree) - 1
    vals, vecs = sla.eigh(k, m, subset_by_index=None if hi is None else [0, hi])
    full = np.zeros((model.ndof, vecs.shape[1]))
    full[model.free] = vecs
    return Modes(np.sqrt(np.clip(vals, 0.0, None)), full)
