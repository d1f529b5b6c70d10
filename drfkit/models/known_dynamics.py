"""A filter that knows the pendulum: the DRF's encoder, an extended Kalman filter with the benchmark's
true equations (the model-based reference the paper's related work names: BackpropKF, a learned
encoder with a covariance and a known transition).

It splits the distance between a learned filter and the limit on pixels into what the encoder loses
(this model) and what a learned transition loses on top (the DRF).

    encoder (the DRF family's image encoder) -> w_t (B, T, 2) an observation of (cos theta, sin theta),
                                                r_t (B, T, 2) its variance (one value per frame, repeated)
    state x = (theta, omega), P (B, 2, 2)
    predict: x <- f(x), the benchmark's pendulum over one frame (theta'' = -c sin theta - friction
             theta', RK4 in ``RK4_SUBSTEPS``), F = df/dx propagated alongside; P <- F P F^T + Q,
             Q = diag(q_theta, q_omega), q_omega = 0.1^2 the benchmark's velocity noise per frame
    update:  h(x) = (cos theta, sin theta), H = dh/dx = [[-sin theta, 0], [cos theta, 0]],
             ``drfkit.core.filter.ekf_update`` (Joseph form)
    start:   theta_0 = atan2(w_0), P_0 = diag(r_0, init_velocity_var), omega_0 = 0
    output:  mean = (cos theta, sin theta), sigma = sqrt(diag(H P H^T)) + SIGMA_FLOOR

The paper's other future-work lever, "driving the learned state transition network towards a known
dynamics model", is ``transition='learned'``: the same filter with a learned transition in the same state,
x' = x + g(x), g an MLP of (sin theta, cos theta, omega) started at zero (a random walk) with its Jacobian
carried analytically, and ``pull`` > 0 adds pull x mean ||x' - f(x)||^2 (the angle and a frame's worth of
velocity) over a grid of the states the pendulum visits to the training loss (``regulariser``): 0 leaves
the transition free, a large pull drives it to the true one.

The output is the filter's own belief, no learned decoder: the model has no dropout, so its
Monte Carlo samples are identical and its epistemic spread is 0 (``head`` accepts the arguments the
DRF family's head takes). ``observation_output`` (w_t, sqrt r_t) is what an observation loss fits
(``TrainConfig.obs_weight``), so that r_t is trained as a per-frame variance.
"""
from __future__ import annotations

import math
from typing import Any

import torch
from torch import nn

from drfkit.core.filter import ekf_update, gain_update
from drfkit.data import pendulum_physics as pend
from drfkit.models.parts import IMAGE_DOWNSAMPLES, OUTPUT_LOG_R_RANGE, SIGMA_FLOOR, check_n_samples
from drfkit.models.filtering import run_filter_loop, select_forced, stack_steps
from drfkit.models.sequence import SequenceModel, make_encoder
from drfkit.models.spec import ModelSpec

RK4_SUBSTEPS = 2  # RK4: against the generator's 500 semi-implicit Euler steps < 1e-4 rad after a frame (as 5 steps; tested)
LOG_R_RANGE = OUTPUT_LOG_R_RANGE  # r of (cos, sin) on a bounded log scale, in the output's units
_PENDULUM_C = pend.GRAVITY * pend.LENGTH * pend.MASS / (pend.MASS * pend.LENGTH ** 2 / 3.0)
TRANSITIONS = ("true", "learned")
# from rest at any angle the pendulum's speed stays below sqrt(4 c); the pull's grid reaches 10 % beyond
OMEGA_MAX = 1.1 * math.sqrt(4.0 * _PENDULUM_C)
PULL_GRID = (32, 24)  # angles x velocities where the pull compares the learned transition with the true one


def pendulum_step(theta: torch.Tensor, omega: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """One frame of the benchmark's noiseless pendulum from (theta, omega) (B,), with its Jacobian.

    Returns theta', omega' (B,) and F = d(theta', omega') / d(theta, omega) (B, 2, 2), RK4 in
    ``RK4_SUBSTEPS`` steps with the tangents carried through every stage (forward mode by hand)."""
    h, c, fr = pend.FRAME_DT / RK4_SUBSTEPS, _PENDULUM_C, pend.FRICTION
    one, zero = torch.ones_like(theta), torch.zeros_like(theta)
    # tangents of (theta, omega) with respect to the start, as columns: d/dtheta0, d/domega0
    t_th, t_om = torch.stack([one, zero], -1), torch.stack([zero, one], -1)           # (B, 2) each

    def accel(th, om, d_th, d_om):
        return -c * torch.sin(th) - fr * om, -c * torch.cos(th).unsqueeze(-1) * d_th - fr * d_om

    for _ in range(RK4_SUBSTEPS):
        k1t, dk1t = omega, t_om
        k1v, dk1v = accel(theta, omega, t_th, t_om)
        k2t, dk2t = omega + 0.5 * h * k1v, t_om + 0.5 * h * dk1v
        k2v, dk2v = accel(theta + 0.5 * h * k1t, omega + 0.5 * h * k1v, t_th + 0.5 * h * dk1t, t_om + 0.5 * h * dk1v)
        k3t, dk3t = omega + 0.5 * h * k2v, t_om + 0.5 * h * dk2v
        k3v, dk3v = accel(theta + 0.5 * h * k2t, omega + 0.5 * h * k2v, t_th + 0.5 * h * dk2t, t_om + 0.5 * h * dk2v)
        k4t, dk4t = omega + h * k3v, t_om + h * dk3v
        k4v, dk4v = accel(theta + h * k3t, omega + h * k3v, t_th + h * dk3t, t_om + h * dk3v)
        theta = theta + h / 6.0 * (k1t + 2 * k2t + 2 * k3t + k4t)
        omega = omega + h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
        t_th = t_th + h / 6.0 * (dk1t + 2 * dk2t + 2 * dk3t + dk4t)
        t_om = t_om + h / 6.0 * (dk1v + 2 * dk2v + 2 * dk3v + dk4v)
    return theta, omega, torch.stack([t_th, t_om], dim=-2)


class LearnedTransition(nn.Module):
    """x' = x + g(x) of (theta, omega) (B,) each, g = Linear(tanh(Linear(sin theta, cos theta, omega /
    OMEGA_MAX))), its output layer zero at the start (x' = x), with F = dx'/dx (B, 2, 2)."""

    def __init__(self, hidden: int):
        super().__init__()
        self.inner, self.outer = nn.Linear(3, hidden), nn.Linear(hidden, 2)
        nn.init.zeros_(self.outer.weight)
        nn.init.zeros_(self.outer.bias)

    def forward(self, theta: torch.Tensor, omega: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        s, c = torch.sin(theta), torch.cos(theta)
        a = torch.tanh(self.inner(torch.stack([s, c, omega / OMEGA_MAX], -1)))                # (B, H)
        g = self.outer(a)                                                                   # (B, 2)
        zero = torch.zeros_like(theta)
        d_phi = torch.stack([torch.stack([c, zero], -1), torch.stack([-s, zero], -1),
                             torch.stack([zero, torch.full_like(theta, 1.0 / OMEGA_MAX)], -1)], -2)  # (B, 3, 2)
        d_g = self.outer.weight @ ((1.0 - a.square()).unsqueeze(-1) * (self.inner.weight @ d_phi))  # (B, 2, 2)
        return theta + g[:, 0], omega + g[:, 1], torch.eye(2, dtype=theta.dtype) + d_g


class KnownDynamicsFilter(SequenceModel):
    """The DRF family's encoder with an EKF on the pendulum's true equations (module docstring)."""

    kind = "known_dynamics"
    # the model-based reference of the book's protocol (drfkit.methods.protocols); the paper's trains it at its defaults
    spec = ModelSpec("Known dynamics (EKF)", "tab:purple", studies=("pendulum",), reference=True,
                     protocols={"book": "fit_known_dynamics_wide"})
    stream_follows = ("features", "filter_steps")

    def __init__(self, input_kind: str = "pendulum", out_dim: int = 2, feature_dim: int = 64,
                 image_downsample: str = "pool", q_theta: float = 1e-6,
                 q_omega: float = pend.TRANSITION_NOISE_STD ** 2, init_velocity_var: float = 25.0,
                 learn_q: bool = False, encoder_channels: int = 12, transition: str = "true",
                 transition_hidden: int = 32, pull: float = 0.0):
        if input_kind != "pendulum" or out_dim != 2:
            raise ValueError("the known-dynamics filter knows the pendulum only: input_kind 'pendulum', out_dim 2 "
                             f"(got {input_kind!r}, {out_dim!r})")
        if isinstance(feature_dim, bool) or not isinstance(feature_dim, int) or feature_dim < 1:
            raise ValueError(f"feature_dim must be a positive int, got {feature_dim!r}")
        if image_downsample not in IMAGE_DOWNSAMPLES:
            raise ValueError(f"image_downsample must be one of {IMAGE_DOWNSAMPLES}, got {image_downsample!r}")
        for name, value in (("q_theta", q_theta), ("q_omega", q_omega), ("init_velocity_var", init_velocity_var)):
            if not (isinstance(value, (int, float)) and value > 0):
                raise ValueError(f"{name} must be a variance > 0, got {value!r}")
        if not isinstance(learn_q, bool):
            raise ValueError(f"learn_q must be True or False, got {learn_q!r}")
        if transition not in TRANSITIONS:
            raise ValueError(f"transition must be one of {TRANSITIONS}, got {transition!r}")
        if isinstance(transition_hidden, bool) or not isinstance(transition_hidden, int) or transition_hidden < 1:
            raise ValueError(f"transition_hidden must be a positive int, got {transition_hidden!r}")
        if not (isinstance(pull, (int, float)) and pull >= 0) or (pull > 0 and transition != "learned"):
            raise ValueError(f"pull must be >= 0 and only pulls a learned transition (transition='learned'), got "
                             f"pull={pull!r} with transition={transition!r}")
        super().__init__(dict(input_kind=input_kind, out_dim=out_dim, feature_dim=feature_dim,
                              image_downsample=image_downsample, q_theta=float(q_theta), q_omega=float(q_omega),
                              init_velocity_var=float(init_velocity_var), learn_q=learn_q)
                         | ({"encoder_channels": encoder_channels} if encoder_channels != 12 else {})
                         | ({"transition": transition, "transition_hidden": transition_hidden, "pull": float(pull)}
                            if transition != "true" else {}))
        self.latent = 2  # what the diagnostics call the observed dims: (cos, sin)
        self.encoder = make_encoder(input_kind, feature_dim, image_downsample, encoder_channels)
        self.obs_mean = nn.Linear(feature_dim, 2)
        self.obs_log_r = nn.Linear(feature_dim, 1)
        log_q = torch.log(torch.tensor([q_theta, q_omega]))
        self.log_q = nn.Parameter(log_q) if learn_q else nn.Buffer(log_q)
        self.init_velocity_var = float(init_velocity_var)
        self.transition, self.pull = transition, float(pull)
        if transition == "learned":
            self.learned = LearnedTransition(transition_hidden)
            theta = torch.linspace(-math.pi, math.pi, PULL_GRID[0] + 1)[:-1]
            omega = torch.linspace(-OMEGA_MAX, OMEGA_MAX, PULL_GRID[1])
            grid_theta, grid_omega = (g.flatten() for g in torch.meshgrid(theta, omega, indexing="ij"))
            self.pull_grid = nn.Buffer(torch.stack([grid_theta, grid_omega], -1), persistent=False)
            self.pull_target = nn.Buffer(torch.stack(pendulum_step(grid_theta, grid_omega)[:2], -1), persistent=False)

    def regulariser(self) -> torch.Tensor | float:
        """pull x mean over the grid of (angle error of x')^2 + (FRAME_DT x velocity error)^2: how far the
        learned transition is from the true one where the pendulum goes (0 for the true transition)."""
        if self.transition != "learned" or self.pull == 0.0:
            return 0.0
        theta, omega, _ = self.learned(self.pull_grid[:, 0], self.pull_grid[:, 1])
        d_theta = torch.remainder(theta - self.pull_target[:, 0] + math.pi, 2 * math.pi) - math.pi
        d_omega = (omega - self.pull_target[:, 1]) * pend.FRAME_DT
        return self.pull * (d_theta.square() + d_omega.square()).mean()

    # ---------------------------------------------------------------- observation
    def observe(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """w (B, T, 2) an observation of (cos theta, sin theta), r (B, T, 2) its variance (one per frame)."""
        x = self.encoder(inputs)
        lo, hi = LOG_R_RANGE
        r = torch.exp(lo + (hi - lo) * torch.sigmoid(self.obs_log_r(x)))
        return self.obs_mean(x), r.expand(*r.shape[:-1], 2)

    def observation_output(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(w, sqrt r) (B, T, 2): the encoder's per-frame estimate and its sigma, for an observation loss."""
        w, r = self.observe(inputs)
        return w, r.sqrt()

    # ---------------------------------------------------------------- filter
    def _start(self, w0: torch.Tensor, r0: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        theta = torch.atan2(w0[:, 1], w0[:, 0])
        x = torch.stack([theta, torch.zeros_like(theta)], -1)                               # (B, 2)
        P = torch.diag_embed(torch.stack([r0[:, 0], torch.full_like(theta, self.init_velocity_var)], -1))
        return x, P

    def _step(self, x, P, w, r, q_scale: float = 1.0, gain_t: torch.Tensor | None = None):
        """Predict with the true pendulum, update with (w, r) (B, 2): x, P, K (B, 2, 2), F and the prior
        (x, P) before the update. ``gain_t`` (B,) a forced gain (``drfkit.models.filtering``; NaN rows: the EKF's
        own): K = g [H_theta; 0], the angle moved by g times the innovation's tangent component, the velocity not
        updated (g = 0: the prediction alone), Joseph form (``gain_update``)."""
        step = pendulum_step if self.transition == "true" else self.learned
        theta, omega, F = step(x[:, 0], x[:, 1])
        prior = torch.stack([theta, omega], -1)
        p_prior = F @ P @ F.mT + torch.diag_embed((self.log_q.exp() * q_scale).expand_as(prior))
        s, c = torch.sin(theta), torch.cos(theta)
        zero = torch.zeros_like(theta)
        H = torch.stack([torch.stack([-s, zero], -1), torch.stack([c, zero], -1)], -2)       # (B, 2, 2)
        innovation = w - torch.stack([c, s], -1)
        if gain_t is None or torch.isnan(gain_t).all():
            x, P, K = ekf_update(prior, p_prior, innovation, H, r)
        else:
            g = torch.nan_to_num(gain_t, nan=0.0)
            K_forced = torch.stack([torch.stack([-s * g, c * g], -1), torch.zeros_like(H[:, 0])], -2)   # (B, 2, 2)
            forced = (*gain_update(prior, p_prior, innovation, H, r, K_forced), K_forced)
            own = None if not torch.isnan(gain_t).any() else ekf_update(prior, p_prior, innovation, H, r)
            x, P, K = select_forced(gain_t, forced, own)
        return x, P, K, F, (prior, p_prior)

    def filter_steps(self, w: torch.Tensor, r: torch.Tensor, return_gains: bool = False,
                     return_prior: bool = False, q_scale: float = 1.0,
                     gain: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """The EKF on w, r (B, T, 2); ``gain`` (B, T) a forced gain per frame (``_step``; NaN = the EKF's own). Always 'x' (B, T, 2) = (theta, omega) and 'p' (B, T, 2, 2).
        ``return_gains``: 'gains' K (B, T, 2, 2) (state x observation; t = 0: the start's, theta from w_0),
        'F' (B, T-1, 2, 2); ``return_prior``: 'x_prior' (B, T-1, 2), 'p_prior' (B, T-1, 2, 2)."""
        if w.ndim != 3 or w.shape[-1] != 2 or r.shape != w.shape:
            raise ValueError(f"w and r must both be (B, T, 2), got {tuple(w.shape)} and {tuple(r.shape)}")

        def start(w0, r0):
            x, P = self._start(w0, r0)
            record = {"x": x, "p": P}
            if return_gains:  # at t = 0 the angle is taken from w_0 whole: the gain on the tangent is 1
                eye = torch.zeros_like(P)
                eye[:, 0, 0] = -torch.sin(x[:, 0])
                eye[:, 0, 1] = torch.cos(x[:, 0])
                record["gains"] = eye
            return (x, P), record

        def step(carry, w_t, r_t, g_t=None):
            x, P, K, F, (prior, p_prior) = self._step(*carry, w_t, r_t, q_scale, g_t)
            record = {"x": x, "p": P}
            if return_gains:
                record["gains"], record["F"] = K, F
            if return_prior:
                record["x_prior"], record["p_prior"] = prior, p_prior
            return (x, P), record

        first, steps = run_filter_loop(start, step, w, r, gain)
        b = w.shape[0]
        out = {"x": stack_steps(steps, "x", w.new_empty(b, 0, 2), first["x"]),
               "p": stack_steps(steps, "p", w.new_empty(b, 0, 2, 2), first["p"])}
        if return_gains:
            out["gains"] = stack_steps(steps, "gains", w.new_empty(b, 0, 2, 2), first["gains"])
            out["F"] = stack_steps(steps, "F", w.new_empty(b, 0, 2, 2))
        if return_prior:
            out["x_prior"] = stack_steps(steps, "x_prior", w.new_empty(b, 0, 2))
            out["p_prior"] = stack_steps(steps, "p_prior", w.new_empty(b, 0, 2, 2))
        return out

    @staticmethod
    def belief(x: torch.Tensor, P: torch.Tensor) -> torch.Tensor:
        """h = [cos theta, sin theta, omega, log P_theta_theta, log P_omega_omega] (..., 5) of a belief."""
        theta = x[..., 0]
        return torch.stack([torch.cos(theta), torch.sin(theta), x[..., 1],
                            torch.log(P[..., 0, 0]), torch.log(P[..., 1, 1])], -1)

    def features(self, inputs, return_gains=False):
        tr = self.filter_steps(*self.observe(inputs), return_gains=return_gains)
        return self.belief(tr["x"], tr["p"]), tr.get("gains")

    def head(self, h: torch.Tensor, n_samples: int = 0, dropout_p: float | None = None,
             uniforms=None) -> tuple[torch.Tensor, torch.Tensor]:
        """mean = (cos, sin), sigma = sqrt(diag(H P H^T)) + SIGMA_FLOOR (..., 2); n_samples S > 0:
        (S, ..., 2), S identical copies (no dropout: the epistemic spread is 0)."""
        check_n_samples(n_samples)
        mean = h[..., :2]
        var_theta = h[..., 3].exp().unsqueeze(-1)
        sigma = torch.sqrt(var_theta * mean.flip(-1) ** 2) + SIGMA_FLOOR                     # |dh/dtheta| = (|sin|, |cos|)
        if n_samples:
            return mean.expand(n_samples, *mean.shape), sigma.expand(n_samples, *sigma.shape)
        return mean, sigma

    @property
    def default_dropout_p(self) -> float:
        return 0.0

    def forward(self, inputs: torch.Tensor, gain: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """(mean, sigma) (B, T, 2); ``gain`` (B, T) a forced gain per frame (``filter_steps``; None: the EKF's own)."""
        if gain is None:
            return super().forward(inputs)
        tr = self.filter_steps(*self.observe(inputs), gain=gain)
        return self.head(self.belief(tr["x"], tr["p"]))

    def forward_with_prior(self, inputs: torch.Tensor, gain: torch.Tensor | None = None):
        """(mean, sigma) of the posterior (B, T, 2) and of the one-step prior (B, T-1, 2); ``gain`` as ``forward``'s."""
        tr = self.filter_steps(*self.observe(inputs), return_prior=True, gain=gain)
        return self.head(self.belief(tr["x"], tr["p"])), self.head(self.belief(tr["x_prior"], tr["p_prior"]))

    def filter_diagnostics(self, inputs: torch.Tensor) -> dict[str, torch.Tensor]:
        """What ``drfkit.methods.diagnostics.filter_trace`` reads of a filter: 'r' (B, T), 'gain' (B, T)
        = trace(H K), the share of an innovation along the rod's tangent that moves the angle (1 at t = 0),
        'prior_err' / 'static_err' (B, T-1) = ||h(f(x_{t-1})) - w_t|| / ||h(x_{t-1}) - w_t||,
        'spectral_radius' of F_t, 'h' the features."""
        w, r = self.observe(inputs)
        tr = self.filter_steps(w, r, return_gains=True, return_prior=True)
        theta = tr["x"][..., 0]
        tangent = torch.stack([-torch.sin(theta), torch.cos(theta)], -1)                   # (B, T, 2)
        gain = (tr["gains"][..., 0, :] * tangent).sum(-1)
        gain[:, 0] = 1.0
        prior_theta, last_theta = tr["x_prior"][..., 0], theta[:, :-1]
        unit = lambda a: torch.stack([torch.cos(a), torch.sin(a)], -1)                     # noqa: E731
        F = tr["F"].flatten(0, 1).double()
        return {"r": r[..., 0], "gain": gain,
                "prior_err": (unit(prior_theta) - w[:, 1:]).norm(dim=-1),
                "static_err": (unit(last_theta) - w[:, 1:]).norm(dim=-1),
                "spectral_radius": torch.linalg.eigvals(F).abs().amax(-1) if len(F) else F.new_empty(0),
                "h": self.belief(tr["x"], tr["p"])}

    observed_dims = 2  # the observation (cos theta, sin theta)

    def observed_truth(self, w_clean: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        """The true (cos theta, sin theta) (B, T, 2): the observation's own units."""
        return targets

    def belief_variance(self, h: torch.Tensor) -> torch.Tensor:
        """The log variances (..., 2) of a belief (..., 5)."""
        return h[..., 3:]

    def with_belief_variance(self, h: torch.Tensor, log_var: torch.Tensor) -> torch.Tensor:
        """The belief with its log variances replaced (the head's mean does not read them)."""
        return torch.cat([h[..., :3], log_var], -1)

    def filter_internals(self, w: torch.Tensor, r: torch.Tensor, q_scale: float = 1.0,
                         gain: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """The EKF on w, r (B, T, 2) with Q times ``q_scale`` and the forced ``gain`` (B, T) (NaN = its own), seen in the observation's space (``drfkit.methods.dissection``):
        'prior' (B, T-1, 2) h(f(x_{t-1})), 'p_prior' (B, T-1, 2) diag(H P_prior H^T), 'q' (B, T-1, 2)
        diag(H Q H^T), 'gain' (B, T, 2) diag(H K) (how much of an innovation reaches the estimate; 1 at
        t = 0), 'h' the belief the head reads and 'h_prior' (B, T-1, 5) the one-step prior's."""
        tr = self.filter_steps(w, r, return_gains=True, return_prior=True, q_scale=q_scale, gain=gain)
        theta = tr["x_prior"][..., 0]
        s, c = torch.sin(theta), torch.cos(theta)
        tangent_sq = torch.stack([s * s, c * c], -1)                                          # diag(H e_theta e_theta^T H^T)
        H_prior = torch.stack([-s, c], -1)                                                    # (B, T-1, 2): H's theta column
        gain = (H_prior.unsqueeze(-1) * tr["gains"][:, 1:, :1, :]).diagonal(dim1=-2, dim2=-1)  # diag(H K)
        return {"prior": torch.stack([c, s], -1), "p_prior": tr["p_prior"][..., 0, 0].unsqueeze(-1) * tangent_sq,
                "q": self.log_q[0].exp() * q_scale * tangent_sq,
                "gain": torch.cat([torch.ones_like(w[:, :1]), gain], 1),
                "h": self.belief(tr["x"], tr["p"]), "h_prior": self.belief(tr["x_prior"], tr["p_prior"])}

    # ---------------------------------------------------------------- streaming
    def initial_carry(self, frame: torch.Tensor):
        self._check_streaming(frame)
        w, r = self.observe(frame)
        return self._start(w[:, 0], r[:, 0])

    def stream_step(self, frame: torch.Tensor, carry):
        self._check_streaming(frame)
        w, r = self.observe(frame)
        x, P, _, _, _ = self._step(*carry, w[:, 0], r[:, 0])
        return self.belief(x, P).unsqueeze(1), (x, P)


__all__ = ["KnownDynamicsFilter", "LearnedTransition", "LOG_R_RANGE", "RK4_SUBSTEPS", "TRANSITIONS", "pendulum_step"]
