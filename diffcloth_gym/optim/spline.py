"""End-effector trajectories as cubic Hermite splines (paper Appendix B.2, Hat and Sock): per
effector an endpoint and two tangents (9 numbers), the start being the effector's position
when the rollout starts."""

from __future__ import annotations

import numpy as np

from diffcloth_gym.errors import InputError
from diffcloth_gym.optim.parameterization import Inputs, check_bounds


def hermite_basis(steps: int) -> np.ndarray:
    """(steps, 4) weights of (p0, t1, p_end, t2) at s = (n + 1) / steps, n = 0 .. steps - 1
    (the target of step n is where the effector is at the end of the step: s = 1 is the
    endpoint)."""
    s = np.arange(1, steps + 1) / steps
    s2, s3 = s * s, s * s * s
    return np.stack([2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2], axis=1)


class HermiteSpline:
    """Attachment targets of ``k`` effectors along cubic Hermite splines.

    ``theta`` holds, per effector in attachment order, ``(d, t1, t2)``: the endpoint's
    displacement from the start ``d = p_end - p0`` and the tangents at the start and the end
    (units of length per the whole rollout: the spline parameter runs from 0 to 1 over it).
    Displacements rather than endpoints, so one symmetric bound serves every effector.
    Bounds: ``reach`` on each displacement component, ``tangent`` on each tangent component.

    ``p(s) = h00(s) p0 + h10(s) t1 + h01(s) (p0 + d) + h11(s) t2``; the gradient is
    ``dL/dtheta = sum_n basis_n dL/dtarget_n`` (the backward's ``attachment_targets``).
    """

    def __init__(self, start, reach: float = 1.0, tangent: float = 2.0):
        start = np.asarray(start, dtype=np.float64)
        if start.ndim != 2 or start.shape[1] != 3 or not np.all(np.isfinite(start)):
            raise InputError(f"start must be a finite (k, 3) array of effector positions, got shape {start.shape}")
        self.start = start.copy()
        self.k = len(start)
        self.size = 9 * self.k
        self.names = [f"effector{e}_{part}_{c}" for e in range(self.k) for part in ("d", "t1", "t2") for c in "xyz"]
        lo, hi = [], []
        for _ in range(self.k):
            lo += [-reach] * 3 + [-tangent] * 6
            hi += [reach] * 3 + [tangent] * 6
        self._bounds = check_bounds("HermiteSpline", lo, hi, self.size)

    @property
    def bounds(self):
        return self._bounds

    def _parts(self, theta):
        t = np.asarray(theta, dtype=np.float64).reshape(self.k, 3, 3)
        return t[:, 0], t[:, 1], t[:, 2]  # d, t1, t2: each (k, 3)

    def targets(self, theta, steps: int) -> np.ndarray:
        """(steps, k, 3) attachment targets."""
        d, t1, t2 = self._parts(theta)
        b = hermite_basis(steps)
        p0 = self.start
        return (b[:, 0, None, None] * p0 + b[:, 1, None, None] * t1 + b[:, 2, None, None] * (p0 + d)
                + b[:, 3, None, None] * t2)

    def inputs(self, theta, steps: int) -> Inputs:
        return Inputs(targets=self.targets(theta, steps))

    def chain(self, theta, grads: dict, steps: int) -> np.ndarray:
        g = np.asarray(grads["attachment_targets"])  # (steps, k, 3)
        b = hermite_basis(steps)
        gd = np.einsum("n,nkc->kc", b[:, 2], g)
        g1 = np.einsum("n,nkc->kc", b[:, 1], g)
        g2 = np.einsum("n,nkc->kc", b[:, 3], g)
        return np.stack([gd, g1, g2], axis=1).reshape(-1)
