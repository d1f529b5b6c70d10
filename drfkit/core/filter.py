"""Differentiable, batched Kalman filter with an identity observation model (H = I).

The deep recursive filter runs a Kalman filter on a learned latent state: the encoder
emits an observation ``w`` of the latent state with noise covariance ``R``, the state
transition network emits ``F`` and the process noise ``Q``. With H = I the equations are

    predict:  z <- F z,            P <- F P F^T + Q
    update:   S = P + R,  K = P S^-1,  z <- z + K (w - z),
              P <- (I - K) P (I - K)^T + K R K^T        (Joseph form)

Shapes (``n`` = latent size, ``...`` = any leading batch dims, broadcast together):

    z, w : (..., n)          state mean, observation
    P, F : (..., n, n)       state covariance, transition matrix
    Q, R : (..., n)          diagonal noise (the diagonal entries), or
           (..., n, n)       full noise covariance

A noise argument is *diagonal* when it is 1-D or has as many dims as the batched
vectors (``z``, and ``w`` in the update), *full* when it has one dim more. So to share
one diagonal Q of shape (n,) across a batch, pass it as is; to share a full one, pass
(n, n) with a batched z only if ``z.ndim == 1``, otherwise add a leading size-1 dim.

P and full R/Q must be symmetric positive (semi-)definite; every P this module returns
is symmetrised ``(P + P^T) / 2``. Everything works in float32 and float64, on any device,
and is differentiable in every argument (first derivatives: the gain, and the whole fused
step, have hand-written backwards, see ``_TransposedGain`` and ``_FusedStep``; double
backward is not supported).

Numerics: K is obtained from a Cholesky factor of S, by triangular solves in the
composed functions and by the inverse of the factor (``cholesky_inverse``) in the fused
step that ``kalman_step`` uses for the DRF's batched diagonal case (see ``_FusedStep``);
the Joseph form keeps P positive definite even when K carries rounding error (the
error enters P only to second order); the short form P - K P loses definiteness in
float32 when the noise scales span many decades. If the Cholesky factorisation of S
fails (info > 0), the failing batch items are retried once with a small jitter on the
diagonal of S (see ``CHOLESKY_JITTER``); a second failure, or NaN/inf in S, raises a
ValueError instead of returning NaN.
"""
from __future__ import annotations

import torch
from torch.autograd.function import once_differentiable

__all__ = ["kalman_predict", "kalman_update", "kalman_step", "kalman_step_unchecked", "ekf_update", "gain_update",
           "CHOLESKY_JITTER"]

# Multiplier of the jitter added to the diagonal of S when its Cholesky factorisation
# fails (S numerically not positive definite, e.g. float32 with badly scaled P and R).
# The jitter is CHOLESKY_JITTER * sqrt(machine epsilon) * max(diag S), i.e. about
# 1.5e-8 * max(diag S) in float64 and 3.5e-4 * max(diag S) in float32. It only touches
# the items that failed, and only S (the Joseph update uses the caller's R).
CHOLESKY_JITTER = 1.0


# --------------------------------------------------------------------------- checks

def _shape(t: torch.Tensor) -> str:
    return "(" + ", ".join(str(s) for s in t.shape) + ")"


def _require_tensor(name: str, t) -> None:
    if not isinstance(t, torch.Tensor):
        raise TypeError(f"{name} must be a torch.Tensor, got {type(t).__name__}; "
                        f"wrap it with torch.as_tensor(...)")
    if not t.is_floating_point():
        raise TypeError(f"{name} must be a floating point tensor (float32/float64), got {t.dtype}")


def _check_vector(name: str, t: torch.Tensor, n: int) -> None:
    if t.ndim < 1 or t.shape[-1] != n:
        raise ValueError(f"{name} must have shape (..., {n}), got {_shape(t)}")


def _state_size(z: torch.Tensor) -> int:
    if z.ndim < 1:
        raise ValueError("z must have shape (..., n), got a 0-dim tensor; use z.reshape(1) for n = 1")
    return z.shape[-1]


def _check_matrix(name: str, t: torch.Tensor, n: int) -> None:
    if t.ndim < 2 or t.shape[-2:] != (n, n):
        raise ValueError(f"{name} must have shape (..., {n}, {n}), got {_shape(t)}")


def _noise_is_diagonal(name: str, t: torch.Tensor, n: int, vec_ndim: int) -> bool:
    """True for a diagonal noise argument, False for a full matrix (see module doc)."""
    if t.ndim == 1 or t.ndim == vec_ndim:
        _check_vector(name, t, n)
        return True
    if t.ndim == vec_ndim + 1:
        _check_matrix(name, t, n)
        return False
    raise ValueError(
        f"{name} has shape {_shape(t)} but the batched vectors have {vec_ndim} dims: pass "
        f"the diagonal as (..., {n}) with {vec_ndim} dims or a full matrix as (..., {n}, {n}) "
        f"with {vec_ndim + 1} dims (add leading size-1 dims to share it across the batch)")


def _check_batch(names: tuple[str, ...], batch_shapes: tuple[torch.Size, ...]) -> None:
    try:
        torch.broadcast_shapes(*batch_shapes)
    except RuntimeError:
        desc = ", ".join(f"{nm} {tuple(s)}" for nm, s in zip(names, batch_shapes))
        raise ValueError(f"batch dims do not broadcast: {desc}") from None


def _check_dtypes(**tensors: torch.Tensor) -> None:
    dtypes = {t.dtype for t in tensors.values()}
    if len(dtypes) > 1:
        desc = ", ".join(f"{k} {t.dtype}" for k, t in tensors.items())
        raise TypeError(f"all arguments must share one dtype, got {desc}; cast them with .to(dtype)")


# --------------------------------------------------------------------------- helpers

def _add_diagonal(A: torch.Tensor, d: torch.Tensor, inplace_ok: bool) -> torch.Tensor:
    """A + diag(d) for A (..., n, n), d (..., n).

    Writing into the diagonal of a fresh intermediate avoids materialising an n x n
    diagonal matrix; it is only legal when A is a temporary whose value autograd did
    not save and when the result keeps A's shape (no broadcasting up).
    """
    if inplace_ok and torch.broadcast_shapes(d.shape[:-1], A.shape[:-2]) == A.shape[:-2]:
        A.diagonal(dim1=-2, dim2=-1).add_(d)
        return A
    return A + torch.diag_embed(d)


def _symmetrise(A: torch.Tensor) -> torch.Tensor:
    return (A + A.mT).mul_(0.5)


def _safe_cholesky(S: torch.Tensor) -> torch.Tensor:
    """Lower Cholesky factor of S (..., n, n), robust to numerically indefinite S.

    If the factorisation fails for some batch items (``info > 0``), those items get
    ``CHOLESKY_JITTER * sqrt(eps) * max(diag S)`` added to their diagonal and are
    factorised once more; if that also fails the input is not a covariance (NaN/inf or
    far from positive definite) and a ValueError is raised rather than returning NaN.
    """
    L, info = torch.linalg.cholesky_ex(S)
    if not bool((info > 0).any()):
        return L
    failed = (info > 0).unsqueeze(-1)  # (..., 1)
    if not bool(torch.isfinite(S).all()):
        raise ValueError("S = P + R contains NaN or inf: check P and R (and what produced them)")
    diag = S.diagonal(dim1=-2, dim2=-1)
    scale = diag.abs().amax(dim=-1, keepdim=True).clamp_min(torch.finfo(S.dtype).tiny)
    jitter = CHOLESKY_JITTER * torch.finfo(S.dtype).eps ** 0.5 * scale * failed
    L, info = torch.linalg.cholesky_ex(S + torch.diag_embed(jitter.expand_as(diag)))
    if bool((info > 0).any()):
        raise ValueError(
            "S = P + R is not positive definite even after adding jitter to its diagonal: "
            "P and R must be symmetric positive (semi-)definite covariances")
    return L


# --------------------------------------------------------------------------- filter

class _TransposedGain(torch.autograd.Function):
    """K^T = S^-1 P with S = P + R, through a Cholesky factor of S.

    A hand-written backward reuses the forward's factor L: for upstream gradient G,
    with Y = S^-1 G (one Cholesky solve), dL/dS = -Y K and dL/dP = Y + dL/dS. Letting
    autograd differentiate cholesky_ex + cholesky_solve instead costs a Cholesky
    backward (several triangular solves) and about doubles the backward time of the
    filter step. The gradients are those of the function on symmetric P and R (as are
    torch's own Cholesky gradients). Only first derivatives are supported.
    """

    @staticmethod
    def forward(ctx, P: torch.Tensor, R: torch.Tensor, r_diag: bool) -> torch.Tensor:
        if r_diag:
            batch = torch.broadcast_shapes(P.shape[:-2], R.shape[:-1])
            S = P.expand(*batch, *P.shape[-2:]).clone()
            S.diagonal(dim1=-2, dim2=-1).add_(R)
        else:
            S = P + R
        L = _safe_cholesky(S)
        Kt = torch.cholesky_solve(P, L)  # S^-1 P = (P S^-1)^T as S and P are symmetric
        ctx.save_for_backward(L, Kt)
        ctx.r_diag = r_diag
        ctx.in_shapes = (P.shape, R.shape)
        return Kt

    @staticmethod
    @once_differentiable
    def backward(ctx, grad_Kt: torch.Tensor):
        L, Kt = ctx.saved_tensors
        P_shape, R_shape = ctx.in_shapes
        Y = torch.cholesky_solve(grad_Kt.contiguous(), L)  # S^-1 G
        grad_S = -(Y @ Kt.mT)
        grad_P = grad_R = None
        if ctx.needs_input_grad[0]:
            grad_P = (Y + grad_S).sum_to_size(P_shape)
        if ctx.needs_input_grad[1]:
            g = grad_S.diagonal(dim1=-2, dim2=-1) if ctx.r_diag else grad_S
            grad_R = g.sum_to_size(R_shape)
        return grad_P, grad_R, None



def kalman_predict(z: torch.Tensor, P: torch.Tensor, F: torch.Tensor, Q: torch.Tensor
                   ) -> tuple[torch.Tensor, torch.Tensor]:
    """Kalman prediction step: z_pred = F z, P_pred = F P F^T + Q (symmetrised).

    z (..., n); P, F (..., n, n); Q (..., n) diagonal or (..., n, n) full.
    Returns z_pred (..., n), P_pred (..., n, n) with the broadcast batch shape.
    """
    for name, t in (("z", z), ("P", P), ("F", F), ("Q", Q)):
        _require_tensor(name, t)
    _check_dtypes(z=z, P=P, F=F, Q=Q)
    n = _state_size(z)
    _check_matrix("P", P, n)
    _check_matrix("F", F, n)
    q_diag = _noise_is_diagonal("Q", Q, n, z.ndim)
    _check_batch(("z", "P", "F", "Q"),
                 (z.shape[:-1], P.shape[:-2], F.shape[:-2], Q.shape[:-1] if q_diag else Q.shape[:-2]))

    z_pred = (F @ z.unsqueeze(-1)).squeeze(-1)
    P_pred = (F @ P) @ F.mT  # fresh tensor, not saved by autograd: safe to modify in place
    if q_diag:
        P_pred = _add_diagonal(P_pred, Q, inplace_ok=True)
    else:
        P_pred = P_pred + Q
    return z_pred, _symmetrise(P_pred)


def kalman_update(z: torch.Tensor, P: torch.Tensor, w: torch.Tensor, R: torch.Tensor
                  ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Kalman update step with H = I (Joseph form), gain by Cholesky solve.

    z, w (..., n); P (..., n, n) symmetric PD; R (..., n) diagonal or (..., n, n) full.
    Returns z_new (..., n), P_new (..., n, n) symmetrised, and the gain K (..., n, n).
    """
    for name, t in (("z", z), ("P", P), ("w", w), ("R", R)):
        _require_tensor(name, t)
    _check_dtypes(z=z, P=P, w=w, R=R)
    n = _state_size(z)
    _check_matrix("P", P, n)
    _check_vector("w", w, n)
    r_diag = _noise_is_diagonal("R", R, n, max(z.ndim, w.ndim))
    _check_batch(("z", "P", "w", "R"),
                 (z.shape[:-1], P.shape[:-2], w.shape[:-1], R.shape[:-1] if r_diag else R.shape[:-2]))

    K = _TransposedGain.apply(P, R, r_diag).mT
    z_new = z + (K @ (w - z).unsqueeze(-1)).squeeze(-1)

    # Joseph form: (I - K) P (I - K)^T + K R K^T. Unlike P - K P it stays positive
    # definite when K is slightly off the optimum (the error enters at second order).
    I_minus_K = -K  # fresh tensor: its diagonal can be shifted in place
    I_minus_K.diagonal(dim1=-2, dim2=-1).add_(1.0)
    P_new = (I_minus_K @ P) @ I_minus_K.mT
    KR = K * R.unsqueeze(-2) if r_diag else K @ R
    P_new = P_new + KR @ K.mT
    return z_new, _symmetrise(P_new), K


def ekf_update(z: torch.Tensor, P: torch.Tensor, innovation: torch.Tensor, H: torch.Tensor, R: torch.Tensor
               ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Kalman update with a general (linearised) observation matrix, Joseph form.

        S = H P H^T + R,   K = P H^T S^-1,   z <- z + K y,
        P <- (I - K H) P (I - K H)^T + K R K^T

    z (..., n); P (..., n, n); innovation y = w - h(z) (..., m); H (..., m, n), the Jacobian of h at
    the prior (an EKF's); R (..., m) diagonal. Returns z_new (..., n), P_new (..., n, n) symmetrised and
    K (..., n, m). The gain comes from a Cholesky solve of S (m is small: the known-dynamics filter's
    m = 2); the Joseph form keeps P positive definite when K carries rounding error, as in
    :func:`kalman_update`. Plain autograd differentiates it.
    """
    for name, t in (("z", z), ("P", P), ("innovation", innovation), ("H", H), ("R", R)):
        _require_tensor(name, t)
    _check_dtypes(z=z, P=P, innovation=innovation, H=H, R=R)
    n, m = _state_size(z), innovation.shape[-1]
    _check_matrix("P", P, n)
    if H.shape[-2:] != (m, n) or R.shape[-1] != m:
        raise ValueError(f"ekf_update: H must be (..., {m}, {n}) and R (..., {m}) for a state of {n} and "
                         f"an innovation of {m}; got H {_shape(H)}, R {_shape(R)}")
    PHt = P @ H.mT                                                        # (..., n, m)
    S = _add_diagonal(H @ PHt, R, inplace_ok=False)                       # (..., m, m)
    K = torch.cholesky_solve(PHt.mT, _safe_cholesky(_symmetrise(S))).mT   # (..., n, m)
    z_new = z + (K @ innovation.unsqueeze(-1)).squeeze(-1)
    I_minus_KH = -(K @ H)
    I_minus_KH.diagonal(dim1=-2, dim2=-1).add_(1.0)
    P_new = (I_minus_KH @ P) @ I_minus_KH.mT + (K * R.unsqueeze(-2)) @ K.mT
    return z_new, _symmetrise(P_new), K


def gain_update(z: torch.Tensor, P: torch.Tensor, innovation: torch.Tensor, H: torch.Tensor, R: torch.Tensor,
                K: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The update with a gain the caller chooses (an intervention: the dissection's clamped or oracle gain,
    the training's skipped updates), Joseph form.

        z <- z + K y,      P <- (I - K H) P (I - K H)^T + K R K^T

    z (..., n); P (..., n, n); innovation y = w - h(z) (..., m); H (..., m, n); R (..., m) diagonal; K (..., n, m).
    The Joseph form is the covariance of z + K y for ANY K (the short form P - K H P holds only at the optimal
    gain), so the reported P is the honest variance of the intervened estimate. K = 0 returns z and P exactly:
    no observation reaches the state, whatever R or the innovation hold. Returns z_new (..., n), P_new (..., n, n)
    symmetrised.
    """
    for name, t in (("z", z), ("P", P), ("innovation", innovation), ("H", H), ("R", R), ("K", K)):
        _require_tensor(name, t)
    _check_dtypes(z=z, P=P, innovation=innovation, H=H, R=R, K=K)
    n, m = _state_size(z), innovation.shape[-1]
    _check_matrix("P", P, n)
    if H.shape[-2:] != (m, n) or R.shape[-1] != m or K.shape[-2:] != (n, m):
        raise ValueError(f"gain_update: H must be (..., {m}, {n}), R (..., {m}) and K (..., {n}, {m}) for a state of "
                         f"{n} and an innovation of {m}; got H {_shape(H)}, R {_shape(R)}, K {_shape(K)}")
    z_new = z + (K @ innovation.unsqueeze(-1)).squeeze(-1)
    I_minus_KH = -(K @ H)
    I_minus_KH.diagonal(dim1=-2, dim2=-1).add_(1.0)
    P_new = (I_minus_KH @ P) @ I_minus_KH.mT + (K * R.unsqueeze(-2)) @ K.mT
    return z_new, _symmetrise(P_new)


def _batched_diagonal(z, P, F, Q, w, R) -> bool:
    """True when the arguments fit the fused step: z, w, Q, R (B, n); P, F (B, n, n); one dtype."""
    if not all(isinstance(t, torch.Tensor) for t in (z, P, F, Q, w, R)) or z.ndim != 2:
        return False
    b, n = z.shape
    return (P.shape == F.shape == (b, n, n) and Q.shape == w.shape == R.shape == (b, n)
            and z.is_floating_point() and len({t.dtype for t in (z, P, F, Q, w, R)}) == 1
            and len({t.device for t in (z, P, F, Q, w, R)}) == 1)


def _bmv(A: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """A v for A (B, n, m), v (B, m) -> (B, n). The row-vector form v^T A^T runs several
    times faster than A @ v[..., None] on CPU for small n."""
    return (v.unsqueeze(-2) @ A.mT).squeeze(-2)


class _FusedStep(torch.autograd.Function):
    """kalman_predict + kalman_update for batched arguments with diagonal Q and R, as one
    autograd node with a hand-derived backward. Shapes: z, q, w, r (B, n); P, F (B, n, n).

    The same equations and Joseph form as the composed functions, with one difference:
    S^-1 from ``cholesky_inverse`` of the Cholesky factor (one LAPACK call per item) instead
    of ``cholesky_solve`` (two triangular solves per item, about 3x slower for a batch of
    30 x 30 on CPU), and then K = I - R S^-1 (exact for H = I, as S - R = P-): a row scaling,
    not a matmul. K's absolute error stays at rounding level; where K is tiny its relative
    error grows, which the Joseph form tolerates (K's error enters P at second order). S^-1
    is kept for the backward, whose solve then is a matmul too. Values and gradients agree
    with the composed path to rounding (tests/test_filter.py, float64 and a float32 run of
    the DRF's size).

    Backward (G = sym(dL/dP_new), g = dL/dz_new, M = I - K, d = w - z-; P-, G, H symmetric).
    The Joseph form J(K) = M P- M^T + K R K^T is stationary in K at the optimal gain
    (dJ = dK (S K^T - P-) + transpose = 0 for K = P- S^-1), so only its explicit
    dependence on P- and R is differentiated; autograd through K would add rounding noise
    at the cost of three batched products. K then gets dL/dK = g d^T (rank one), plus the
    caller's dL/dK when K itself is used:
        J at fixed K:             dL/dP- = M^T G M,  dL/dr = diag(K^T G K)
        z_new = z- + K d:         dL/dw = K^T g,  dL/dz- = g - K^T g
        K = P- S^-1, S = P- + R:  Y = S^-1 (dL/dK)^T,  dL/dP- += Y M,  dL/dr += diag(Y M) - diag(Y);
                                  for dL/dK = g d^T: Y = u g^T, Y M = u v^T (u = S^-1 d,
                                  v = M^T g = dL/dz-); H takes sym(u v^T)
        P- = sym(F P F^T + Q):    H = sym(dL/dP-),  dL/dq = diag H,  dL/dF = H F (P + P^T),
                                  dL/dP = F^T H F;  z- = F z: dL/dF += g- z^T, dL/dz = F^T g-
    A jittered S (``_safe_cholesky``) makes K slightly suboptimal; the dropped term is then
    of the jitter's size, in a step that is an emergency fallback anyway.
    """

    @staticmethod
    def forward(ctx, z, P, F, q, w, r):
        z_new, P_new, K, saved = fused_step_forward(z, P, F, q, w, r)
        ctx.save_for_backward(*saved)
        ctx.set_materialize_grads(False)
        return z_new, P_new, K

    @staticmethod
    @once_differentiable
    def backward(ctx, g_z, g_P, g_K_out):
        return fused_step_backward(ctx.saved_tensors, g_z, g_P, g_K_out)


def fused_step_forward(z, P, F, q, w, r):
    """The forward of ``_FusedStep``: (z_new, P_new, K, saved), ``saved`` being what
    :func:`fused_step_backward` needs. Also the step of the DRF's whole-sequence recursion
    (``drfkit.models.recursion``), which keeps ``saved`` per step itself."""
    z_pred, P_pred, S = _fused_prior(z, P, F, q, r)
    z_new, P_new, K, (S_inv, I_minus_K, innovation) = _fused_posterior(z_pred, P_pred, _safe_cholesky(S), w, r)
    return z_new, P_new, K, (z, P, F, r, P_pred, S_inv, K, I_minus_K, innovation)


def _fused_prior(z, P, F, q, r):
    """z- = F z (B, n), P- = sym(F P F^T + Q) (B, n, n) and S = P- + R (B, n, n)."""
    z_pred = _bmv(F, z)
    P_pred = (F @ P) @ F.mT
    P_pred.diagonal(dim1=-2, dim2=-1).add_(q)
    P_pred = _symmetrise(P_pred)
    S = P_pred.clone()
    S.diagonal(dim1=-2, dim2=-1).add_(r)
    return z_pred, P_pred, S


def _fused_posterior(z_pred, P_pred, L, w, r):
    """The update from the prior and L, the lower Cholesky factor of S: z_new, P_new (Joseph form),
    K, and (S^-1, I - K, w - z-) for the backward."""
    S_inv = torch.cholesky_inverse(L)
    # K = P- S^-1 = (S - R) S^-1 = I - R S^-1: a row scaling of S^-1 instead of a matmul
    I_minus_K = S_inv * r.unsqueeze(-1)
    K = -I_minus_K
    K.diagonal(dim1=-2, dim2=-1).add_(1.0)
    innovation = w - z_pred
    z_new = z_pred + _bmv(K, innovation)
    P_new = torch.baddbmm((I_minus_K @ P_pred) @ I_minus_K.mT, K * r.unsqueeze(-2), K.mT)
    return z_new, _symmetrise(P_new), K, (S_inv, I_minus_K, innovation)


def kalman_step_unchecked(z: torch.Tensor, P: torch.Tensor, F: torch.Tensor, q: torch.Tensor,
                          w: torch.Tensor, r: torch.Tensor
                          ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """The fused step (z, q, w, r (B, n); P, F (B, n, n)) without a host synchronisation, for
    inference loops that an accelerator runs as one captured graph (``drfkit.models.compiled``).

    ``kalman_step`` asks the host whether every Cholesky factorisation succeeded (to add jitter
    or raise a readable error): one device-to-host copy per step, which stalls a GPU and breaks a
    captured graph. Here the factorisation's status is returned instead: ``failed`` (B,) bool,
    True where S = P- + R was not positive definite (that item's outputs are then not to be
    used). The caller checks it once per sequence and reruns a failed sequence with
    ``kalman_step``, so the results and the errors are the same. Where no item fails, the values
    are ``kalman_step``'s, bit for bit (the same operations in the same order). No autograd node:
    inference only.
    """
    z_pred, P_pred, S = _fused_prior(z, P, F, q, r)
    L, info = torch.linalg.cholesky_ex(S)
    z_new, P_new, K, _ = _fused_posterior(z_pred, P_pred, L, w, r)
    return z_new, P_new, K, info > 0


def fused_step_backward(saved, g_z, g_P, g_K_out, symmetric: bool = False, out_F=None):
    """Gradients (z, P, F, q, w, r) of one fused step from the upstream gradients of
    (z_new, P_new, K), any of which may be None; formulas in ``_FusedStep``'s docstring.

    ``symmetric=True`` declares P and g_P symmetric, as in the DRF's recursion (every P is
    symmetrised, every g_P is F^T H F plus a diagonal, symmetric to rounding): G = g_P and
    P + P^T = 2 P then need no transposed sums (at 50 x 30 x 30 each costs half a product).
    ``out_F`` (B, n, n), contiguous: where dL/dF is written (the recursion's buffer of all
    steps), else a new tensor.
    """
    z, P, F, r, P_pred, S_inv, K, M, innovation = saved
    # dL/dP- is accumulated as a symmetric matrix H: each term below is symmetric (to
    # rounding), so H needs no transposed sum at the end
    H = g_r = g_zp = g_w = None  # dL/dP-, dL/dr, dL/dz-, dL/dw
    if g_P is not None:  # Joseph form at fixed K (its K-derivative vanishes at the optimal gain)
        G = g_P if symmetric else _symmetrise(g_P)
        GM = G @ M
        g_r = ((G - GM) * K).sum(-2)  # diag(K^T G K), as G K = G - G M
        H = M.mT @ GM
    if g_z is not None:  # z_new = z- + K d, and K = P- S^-1 with dL/dK = g d^T of rank one
        g_w = _bmv(K.mT, g_z)
        g_zp = g_z - g_w  # = M^T g = v
        u = _bmv(S_inv, innovation)  # Y = u g^T, Y M = u v^T; its symmetric part enters H
        uv, vu = torch.stack((u, g_zp), dim=-1), torch.stack((g_zp, u), dim=-2)  # (B, n, 2), (B, 2, n)
        H = torch.baddbmm(H, uv, vu, alpha=0.5) if H is not None else (uv @ vu).mul_(0.5)
        g_r_mean = u * g_w
        g_r = g_r_mean.neg_() if g_r is None else g_r.sub_(g_r_mean)  # u (v - g)
    if g_K_out is not None:  # through K = P- S^-1: Y = S^-1 (dL/dK)^T, dL/dP- += Y M
        Y = S_inv @ g_K_out.mT
        YM = Y @ M
        H = _symmetrise(YM) if H is None else H.add_(_symmetrise(YM))
        g_S_diag = YM.diagonal(dim1=-2, dim2=-1) - Y.diagonal(dim1=-2, dim2=-1)
        g_r = g_S_diag if g_r is None else g_r.add_(g_S_diag)
    if H is None:
        return (None,) * 6
    g_q = H.diagonal(dim1=-2, dim2=-1).clone()
    HF = H @ F
    if symmetric:  # H F (P + P^T) = 2 H F P (beta=0: the first argument is ignored)
        g_F = torch.baddbmm(HF, HF, P, beta=0, alpha=2, out=out_F)
    else:
        g_F = torch.bmm(HF, P + P.mT, out=out_F)
    g_Pin = F.mT @ HF
    g_zin = None
    if g_zp is not None:
        g_F.addcmul_(g_zp.unsqueeze(-1), z.unsqueeze(-2))
        g_zin = _bmv(F.mT, g_zp)
    return g_zin, g_Pin, g_F, g_q, g_w, g_r


def kalman_step(z: torch.Tensor, P: torch.Tensor, F: torch.Tensor, Q: torch.Tensor,
                w: torch.Tensor, R: torch.Tensor
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """One full filter step: :func:`kalman_predict` then :func:`kalman_update`.

    Batched arguments with diagonal noise (z, Q, w, R (B, n); P, F (B, n, n); the DRF's
    case) take a fused path with a hand-written backward (``_FusedStep``), about twice as
    fast on CPU; everything else (broadcasting, full noise, other batch shapes) the composed one.
    Returns z_new (..., n), P_new (..., n, n), K (..., n, n).
    """
    if _batched_diagonal(z, P, F, Q, w, R):
        return _FusedStep.apply(z, P, F, Q, w, R)
    z_pred, P_pred = kalman_predict(z, P, F, Q)
    return kalman_update(z_pred, P_pred, w, R)
