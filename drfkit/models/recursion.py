"""The DRF's recursion over a whole sequence -- transition network and Kalman step, t = 1..T-1
-- as one autograd node with a hand-written backward.

Per step the transition network (two LSTM cells on z_{t-1}, then one linear head) gives
F_t and q_t, and the fused Kalman step (``drfkit.core.filter.fused_step_forward``) gives z_t, P_t.
Left to autograd, every step records some forty small nodes (each LSTM gate, slice and
view) and computes the weight gradients of the three layers once per step. Here the
forward runs without a graph and keeps what the backward needs; the backward walks the
steps in reverse, stores each layer's pre-activation gradients for all steps, and forms
the weight gradients at the end as one (out, T*B) x (T*B, in) product per weight -- large
matrix products instead of 3 x (T - 1) small ones (the head's in two, its F_t rows and its
q_t rows: the filter's backward writes dL/dF_t straight into a buffer of its own).

The forward math is shared with inference: :func:`lstm_cell` follows ``torch.nn.LSTMCell``
on the CPU op for op (``linear_hh(h) + linear_ih(x)``, then the gate nonlinearities, tested
equal), and the filter step is the one ``kalman_step`` uses, so the training path and the
per-step inference path (``DeepRecursiveFilter.run_filter``) compute the same values.

Shapes: B batch, T steps, n latent size, H LSTM hidden size, G = 4 H gate width,
O = n * n + n head outputs (F_t's n x n residual, then q_t's pre-activation).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import nn
from torch.autograd.function import once_differentiable

from drfkit.core.filter import fused_step_backward, fused_step_forward
from drfkit.models.parts import VARIANCE_FLOOR, positive_elu


def lstm_cell(x, h, c, w_ih, w_hh, b_ih, b_hh):
    """One ``nn.LSTMCell`` step, x (B, in), h, c (B, H) -> h', c', gate activations
    (B, 4H) in (i, f, g, o) order, tanh(c') (B, H); the last two are for the backward."""
    act = F.linear(h, w_hh, b_hh).add_(F.linear(x, w_ih, b_ih))  # (B, 4H), as ATen's CPU cell
    i, f, g, o = act.unsafe_chunk(4, 1)  # unsafe_chunk, as ATen: its views may be written in place
    i.sigmoid_(), f.sigmoid_(), g.tanh_(), o.sigmoid_()
    c_new = (f * c).add_(i * g)
    tanh_c = c_new.tanh()
    return o * tanh_c, c_new, act, tanh_c


def lstm_cell_backward(dh, dc, act, tanh_c, c_prev, out):
    """dL/dh', dL/dc' (B, H) -> writes dL/d(gate pre-activations) into ``out`` (B, 4H) and
    returns dL/dc_prev; ``act``, ``tanh_c`` as :func:`lstm_cell` returned them."""
    i, f, g, o = act.chunk(4, 1)
    dc = torch.addcmul(dc, dh * o, 1.0 - tanh_c * tanh_c)
    d_i, d_f, d_g, d_o = out.chunk(4, 1)
    torch.mul(dc, g, out=d_i), torch.mul(dc, c_prev, out=d_f), torch.mul(dc, i, out=d_g)
    torch.mul(dh, tanh_c, out=d_o)
    slope = act - act * act  # sigmoid' = s (1 - s) for i, f, o ...
    slope.chunk(4, 1)[2].copy_(1.0 - g * g)  # ... and tanh' = 1 - g^2 for g
    out.mul_(slope)
    return dc * f


class StepRecord(NamedTuple):
    """What the backward needs of one transition step (B rows each)."""
    z_prev: torch.Tensor      # (B, n)  input of cell 1
    h1_prev: torch.Tensor     # (B, H)  cell 1's state in
    c1_prev: torch.Tensor
    act1: torch.Tensor        # (B, 4H) cell 1's gate activations
    tanh_c1: torch.Tensor     # (B, H)
    h1: torch.Tensor          # (B, H)  cell 1's output = input of cell 2
    h2_prev: torch.Tensor
    c2_prev: torch.Tensor
    act2: torch.Tensor
    tanh_c2: torch.Tensor
    h2: torch.Tensor          # (B, H)  input of the head
    q_pre: torch.Tensor       # (B, n)  pre-activation of q_t


def transition_step(z, state, weights, eye, records: list | None = None):
    """Transition network step: z_{t-1} (B, n), state (h1, c1, h2, c2) -> F_t, q_t, state'.

    ``weights`` = (cell 1: w_ih, w_hh, b_ih, b_hh; cell 2: the same; head: weight, bias).
    With a list ``records``, appends this step's :class:`StepRecord` for the backward.
    """
    h1, c1, h2, c2 = state
    h1n, c1n, act1, tc1 = lstm_cell(z, h1, c1, *weights[0:4])
    h2n, c2n, act2, tc2 = lstm_cell(h1n, h2, c2, *weights[4:8])
    out = F.linear(h2n, weights[8], weights[9])  # (B, O)
    n = eye.shape[0]
    F_t = out[:, : n * n].view(-1, n, n) + eye
    q_t = positive_elu(out[:, n * n:], VARIANCE_FLOOR)
    if records is not None:
        records.append(StepRecord(z, h1, c1, act1, tc1, h1n, h2, c2, act2, tc2, h2n, out[:, n * n:]))
    return F_t, q_t, (h1n, c1n, h2n, c2n)


class TransitionNetwork(nn.Module):
    """Previous posterior mean z_{t-1} (B, n) -> F_t (B, n, n), diagonal q_t of Q_t (B, n).

    Two stacked LSTM cells (hidden size ``hidden``) read z_{t-1} only, as in the paper
    ("a dynamical model in the latent embedding"); P_{t-1} does not enter. One fused
    Linear emits both outputs: F_t = I + residual, q_t = ELU(.) + 1 (+ VARIANCE_FLOOR).
    The residual part of the head starts at zero (weights and bias), so an untrained
    filter has F = I: a random-walk prior, which is stable from the first step.
    """

    def __init__(self, latent: int = 30, hidden: int = 64, constant_q: bool = False, q_init: float = 0.1):
        super().__init__()
        self.latent = latent
        self.hidden = hidden
        # constant_q: Q = diag(exp(log_q)), learned but the same at every step and for every
        # sequence (as the RKN's), so the filter cannot buy a large gain by inflating Q on the fly
        self.constant_q = constant_q
        if constant_q:
            self.log_q = nn.Parameter(torch.full((latent,), math.log(q_init)))
        self.cell1 = nn.LSTMCell(latent, hidden)
        self.cell2 = nn.LSTMCell(hidden, hidden)
        self.head = nn.Linear(hidden, latent * latent + latent)
        with torch.no_grad():
            self.head.weight[: latent * latent].zero_()
            self.head.bias[: latent * latent].zero_()
        self.register_buffer("eye", torch.eye(latent), persistent=False)

    def weights(self) -> tuple[torch.Tensor, ...]:
        """The 10 tensors :func:`transition_step` takes: each cell's w_ih, w_hh, b_ih, b_hh, then the head's."""
        c1, c2 = self.cell1, self.cell2
        return (c1.weight_ih, c1.weight_hh, c1.bias_ih, c1.bias_hh,
                c2.weight_ih, c2.weight_hh, c2.bias_ih, c2.bias_hh, self.head.weight, self.head.bias)

    def initial_state(self, batch: int, like: torch.Tensor) -> tuple[torch.Tensor, ...]:
        zeros = like.new_zeros(batch, self.hidden)
        return zeros, zeros, zeros, zeros

    def forward(self, z: torch.Tensor, state: tuple[torch.Tensor, ...]
                ) -> tuple[torch.Tensor, torch.Tensor, tuple[torch.Tensor, ...]]:
        F_t, q_t, state = transition_step(z, state, self.weights(), self.eye)
        if self.constant_q:
            q_t = self.log_q.exp().expand(z.shape[0], self.latent)                    # (B, n)
        return F_t, q_t, state


def _forward_loop(w, r, eye, hidden, weights):
    """The recursion's forward on w, r (B, T, n): means, variances (B, T, n) and, per step
    t = 1..T-1, the transition's :class:`StepRecord` and the filter step's saved tensors."""
    batch, steps, n = w.shape
    w_steps, r_steps = w.unbind(1), r.unbind(1)
    z, P = w_steps[0], torch.diag_embed(r_steps[0])
    zero = w.new_zeros(batch, hidden)
    state = (zero, zero, zero, zero)
    means, variances, records, filter_saved = [z], [r_steps[0]], [], []
    for t in range(1, steps):
        F_t, q_t, state = transition_step(z, state, weights, eye, records)
        z, P, _, saved = fused_step_forward(z, P, F_t, q_t, w_steps[t], r_steps[t])
        filter_saved.append(saved)
        means.append(z)
        variances.append(P.diagonal(dim1=-2, dim2=-1))
    return torch.stack(means, dim=1), torch.stack(variances, dim=1), records, filter_saved


def _backward_loop(g_means, g_vars, records, filter_saved, weights, hidden):
    """Gradients of w, r (B, T, n) and of the 10 transition weights, from those of the
    means and variances (B, T, n), for one :func:`_forward_loop` (T >= 2)."""
    w_ih1, w_hh1, _, _, w_ih2, w_hh2, _, _, w_head, _ = weights
    batch, steps, n = g_means.shape
    g_w, g_r = torch.empty_like(g_means), torch.empty_like(g_vars)
    # pre-activation gradients of every step (cell 1, cell 2, head: F_t's part, q_t's part),
    # for the weight gradients; the fused backward writes dL/dF_t straight into d_F[s]
    d_gates1 = g_means.new_empty(steps - 1, batch, 4 * hidden)
    d_gates2 = torch.empty_like(d_gates1)
    d_F, d_q = g_means.new_empty(steps - 1, batch, n, n), g_means.new_empty(steps - 1, batch, n)
    w_head_F, w_head_q = w_head[: n * n], w_head[n * n:]
    # q = ELU(x) + 1 + floor: slope 1 for x > 0, exp(x) = ELU(x) + 1 otherwise (all steps at once)
    q_pre = torch.stack([rec.q_pre for rec in records])
    q_slope = torch.where(q_pre > 0, 1.0, q_pre.exp())
    g_z, g_P = g_means[:, -1], torch.diag_embed(g_vars[:, -1])
    dh1 = dc1 = dh2 = dc2 = g_means.new_zeros(batch, hidden)  # from step t + 1
    for t in range(steps - 1, 0, -1):
        rec, s = records[t - 1], t - 1
        g_z_prev, g_P_prev, _, g_q, g_w[:, t], g_r[:, t] = fused_step_backward(
            filter_saved[s], g_z, g_P, None, symmetric=True, out_F=d_F[s])
        torch.mul(g_q, q_slope[s], out=d_q[s])
        dh2 = torch.addmm(torch.addmm(dh2, d_F[s].view(batch, n * n), w_head_F), d_q[s], w_head_q)
        dc2 = lstm_cell_backward(dh2, dc2, rec.act2, rec.tanh_c2, rec.c2_prev, out=d_gates2[s])
        dh1 = torch.addmm(dh1, d_gates2[s], w_ih2)
        dh2 = d_gates2[s] @ w_hh2
        dc1 = lstm_cell_backward(dh1, dc1, rec.act1, rec.tanh_c1, rec.c1_prev, out=d_gates1[s])
        dh1 = d_gates1[s] @ w_hh1
        g_z = torch.addmm(g_z_prev, d_gates1[s], w_ih1).add_(g_means[:, s])
        g_P = g_P_prev
        g_P.diagonal(dim1=-2, dim2=-1).add_(g_vars[:, s])
    g_w[:, 0] = g_z
    g_r[:, 0] = g_P.diagonal(dim1=-2, dim2=-1)

    def rows(name):  # one StepRecord field over all steps: ((T-1) B, k)
        return torch.stack([getattr(rec, name) for rec in records]).flatten(0, 1)

    dg1, dg2 = d_gates1.flatten(0, 1), d_gates2.flatten(0, 1)
    dF, dq, h2 = d_F.view(-1, n * n), d_q.flatten(0, 1), rows("h2")
    db1, db2 = dg1.sum(0), dg2.sum(0)  # b_ih and b_hh enter the same sum: equal gradients
    grads = (dg1.T @ rows("z_prev"), dg1.T @ rows("h1_prev"), db1, db1.clone(),
             dg2.T @ rows("h1"), dg2.T @ rows("h2_prev"), db2, db2.clone(),
             torch.cat((dF.T @ h2, dq.T @ h2)), torch.cat((dF.sum(0), dq.sum(0))))
    return g_w, g_r, grads


class _DRFRecursion(torch.autograd.Function):
    """(w, r (B, T, n), the 10 transition weights) -> z, diag P (B, T, n); see the module
    docstring. Starts at z_0 = w_0, P_0 = diag(r_0), LSTM state zero, as ``run_filter``."""

    @staticmethod
    def forward(ctx, w, r, eye, hidden, *weights):
        means, variances, records, filter_saved = _forward_loop(w, r, eye, hidden, weights)
        # saved flat, so that autograd frees them after the backward (or keeps them for retain_graph)
        ctx.save_for_backward(*weights, *(x for rec in records for x in rec),
                              *(x for saved in filter_saved for x in saved))
        ctx.hidden, ctx.n_filter_saved = hidden, len(filter_saved[0]) if filter_saved else 0
        return means, variances

    @staticmethod
    @once_differentiable
    def backward(ctx, g_means, g_vars):
        saved = ctx.saved_tensors
        steps = g_means.shape[1]
        if steps == 1:  # no transition step: z_0 = w_0, P_0 = diag(r_0)
            return (g_means, g_vars, None, None) + (None,) * 10
        n_rec, n_fil = len(StepRecord._fields), ctx.n_filter_saved
        records = [StepRecord(*saved[10 + s * n_rec: 10 + (s + 1) * n_rec]) for s in range(steps - 1)]
        start = 10 + (steps - 1) * n_rec
        filter_saved = [saved[start + s * n_fil: start + (s + 1) * n_fil] for s in range(steps - 1)]
        g_w, g_r, grads = _backward_loop(g_means, g_vars, records, filter_saved, saved[:10], ctx.hidden)
        return (g_w, g_r, None, None, *grads)


def check_observations(w: torch.Tensor, r: torch.Tensor, latent: int) -> None:
    """w and r must both be (B, T, latent): the filter's observations and their variances."""
    if w.ndim != 3 or r.shape != w.shape or w.shape[-1] != latent:
        raise ValueError(f"w and r must both have shape (B, T, {latent}), "
                         f"got {tuple(w.shape)} and {tuple(r.shape)}")


def drf_recursion(transition: TransitionNetwork, w: torch.Tensor, r: torch.Tensor
                  ) -> tuple[torch.Tensor, torch.Tensor]:
    """Posterior means z and variances diag P (B, T, n) of w, r (B, T, n), as one node."""
    check_observations(w, r, transition.latent)
    return _DRFRecursion.apply(w, r, transition.eye, transition.hidden, *transition.weights())
