"""A locally linear transition without memory of its own, as the Recurrent Kalman Network's.

    alpha_t = softmax(W2 ReLU(W1 z_{t-1} + b1) + b2)            (B, K)   K = n_basis
    F_t     = sum_k alpha_t,k A_k                                (B, n, n)
    q_t     = exp(log_q)                                         (B, n)   learned, constant in time

The paper's transition network is two LSTM cells: its hidden state carries a memory of
its own, so F_t can be any function of the past and need not describe how z moves (the
trained paper models have F_t with spectral radius around 2 and predict the next
observation worse than F = I). Here F_t depends on z_{t-1} alone, so whatever the filter
remembers must sit in its state z and covariance P, where the Kalman update weighs it
against each observation: the filter has to model the dynamics to carry information.

The A_k start at I plus a small random perturbation (so the K matrices differ and the
softmax weights receive gradient) and q starts at ``q_init``: an untrained filter is a
random walk, stable from the first step, as ``TransitionNetwork``'s F = I start.
Same interface as ``TransitionNetwork`` (``eye``, ``initial_state``, forward(z, state)); the
state is empty.
"""
from __future__ import annotations

import math

import torch
from torch import nn

BASIS_INIT_STD = 0.01


class BasisTransition(nn.Module):
    """z_{t-1} (B, n) -> F_t (B, n, n), q_t (B, n); see the module docstring."""

    def __init__(self, latent: int = 30, hidden: int = 64, n_basis: int = 16, q_init: float = 0.1):
        super().__init__()
        if isinstance(n_basis, bool) or not isinstance(n_basis, int) or n_basis < 1:
            raise ValueError(f"n_basis must be a positive int, got {n_basis!r}")
        if not q_init > 0:
            raise ValueError(f"q_init must be > 0, got {q_init!r}")
        self.latent, self.hidden, self.n_basis = latent, hidden, n_basis
        self.coefficients = nn.Sequential(nn.Linear(latent, hidden), nn.ReLU(), nn.Linear(hidden, n_basis))
        basis = torch.eye(latent).expand(n_basis, latent, latent).clone()
        self.basis = nn.Parameter(basis + BASIS_INIT_STD * torch.randn(n_basis, latent, latent))
        self.log_q = nn.Parameter(torch.full((latent,), math.log(q_init)))
        self.register_buffer("eye", torch.eye(latent), persistent=False)

    def initial_state(self, batch: int, like: torch.Tensor) -> tuple:
        return ()

    def forward(self, z: torch.Tensor, state: tuple = ()) -> tuple[torch.Tensor, torch.Tensor, tuple]:
        if z.ndim != 2 or z.shape[-1] != self.latent:
            raise ValueError(f"z must have shape (B, {self.latent}), got {tuple(z.shape)}")
        alpha = torch.softmax(self.coefficients(z), dim=-1)            # (B, K)
        F_t = torch.einsum("bk,kij->bij", alpha, self.basis)           # (B, n, n)
        q_t = self.log_q.exp().expand(z.shape[0], self.latent)         # (B, n)
        return F_t, q_t, state
