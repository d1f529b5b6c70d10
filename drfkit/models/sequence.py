"""The DRF family: NoDynamics, LSTMBaseline and DeepRecursiveFilter.

All three share the encoder, the observation heads and the decoder; they differ only in
what sits between the heads and the decoder. Every model (Monoloco included) exposes
the same interface, which the training loop, ``drfkit.uncertainty`` and the timing code
rely on:

    model.config                 dict that ``build_model`` turns back into the model
    model.features(x, return_gains=False) -> (h (B, T, D), gains (B, T, n, n) or None)
                                 the deterministic part, run once per prediction
    model.head(h, n_samples=0, dropout_p=None) -> (mean, sigma)
                                 the stochastic part, (B, T, out) or (S, B, T, out)
    model(x) -> (mean, sigma)    = head(features(x))
    model.loss(mean, sigma, targets, mask=None) -> scalar
    model.default_dropout_p, model.kalman_gains(x)
    model.initial_carry(frame) -> carry
                                 the state carried after a sequence's first frame (B, 1, ...)
    model.stream_step(frame, carry) -> (h (B, 1, D), carry)
                                 one online step on the next frame (B, 1, ...); frame by frame
                                 from initial_carry it gives the h of features(x) on the whole
                                 sequence. A model with no state across frames sets
                                 ``per_frame = True`` and inherits the stateless step; one with
                                 state defines both (see ``SequenceModel``)

Training schedules are not the models' business: ``drfkit.studies.train_config`` holds them.

Inputs: 'pendulum' uint8 images (B, T, 24, 24); 'keypoints' float32 (B, T, 17, 3).
Outputs: pendulum (B, T, 2) = (cos theta, sin theta); pedestrians (B, T, 1) depth (m).
"""
from __future__ import annotations

import math
from typing import Any

import torch
from torch import nn

from drfkit.filter import kalman_step
from drfkit.models.basis import BasisTransition
from drfkit.models.parts import (IMAGE_DOWNSAMPLES, NOISE_HEADS, Decoder, ImageEncoder, KeypointEncoder,
                                 ObservationHeads, check_dropout_p, mean_and_log_variance)
from drfkit.models.recursion import TransitionNetwork, check_observations, drf_recursion

INPUT_KINDS = ("pendulum", "keypoints")

_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)


def make_encoder(input_kind: str, feature_dim: int, image_downsample: str) -> nn.Module:
    if input_kind == "pendulum":
        return ImageEncoder(feature_dim, downsample=image_downsample)
    if input_kind == "keypoints":
        return KeypointEncoder(feature_dim)
    raise ValueError(f"input_kind must be one of {INPUT_KINDS}, got {input_kind!r}")


def frame_mask(mask: torch.Tensor | None, shape: torch.Size) -> torch.Tensor | None:
    """Check a (B, T) bool mask of valid frames against outputs of shape (B, T, out)."""
    if mask is None:
        return None
    if mask.dtype != torch.bool or tuple(mask.shape) != tuple(shape[:2]):
        raise ValueError(f"mask must be a bool tensor of shape {tuple(shape[:2])} (valid frames), "
                         f"got {mask.dtype} {tuple(mask.shape)}")
    if not bool(mask.any()):
        raise ValueError("mask selects no frame: the loss of an empty batch is undefined")
    return mask


def fill_padding(targets: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Targets of padded frames -> 1.0. Padding may hold NaN (or d = 0 for a relative
    loss); even a masked-out term would then send NaN through the backward pass."""
    if mask is None:
        return targets
    return torch.where(mask.unsqueeze(-1), targets, torch.ones_like(targets))


def masked_mean(per_value: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Mean of (B, T, out) over the valid frames (mask (B, T)) and the outputs."""
    if mask is None:
        return per_value.mean()
    # where, not a product: a NaN/inf computed on a padded frame must not leak into the sum
    valid = mask.unsqueeze(-1).expand_as(per_value)
    return torch.where(valid, per_value, 0.0).sum() / (mask.sum() * per_value.shape[-1])


def check_loss_args(mean: torch.Tensor, sigma: torch.Tensor, targets: torch.Tensor) -> None:
    if mean.ndim != 3 or sigma.shape != mean.shape or targets.shape != mean.shape:
        raise ValueError(f"loss expects mean, sigma and targets of one shape (B, T, out); got "
                         f"{tuple(mean.shape)}, {tuple(sigma.shape)}, {tuple(targets.shape)}")


def gaussian_nll(mean: torch.Tensor, sigma: torch.Tensor, targets: torch.Tensor,
                 mask: torch.Tensor | None = None) -> torch.Tensor:
    """The paper's loss: Gaussian NLL log(sqrt(2 pi) sigma) + (y - mean)^2 / (2 sigma^2),
    averaged over the valid frames and the outputs (constant included, so the value is a
    true NLL per scalar: 0.9189 at y = mean, sigma = 1)."""
    check_loss_args(mean, sigma, targets)
    mask = frame_mask(mask, mean.shape)
    targets = fill_padding(targets, mask)
    per_value = torch.log(sigma) + _HALF_LOG_2PI + 0.5 * ((targets - mean) / sigma) ** 2
    return masked_mean(per_value, mask)


def check_frame(frame: torch.Tensor) -> None:
    """A streaming step's input: one frame per sequence, (B, 1, ...)."""
    if not isinstance(frame, torch.Tensor) or frame.ndim != 4 or frame.shape[1] != 1:
        shape = tuple(frame.shape) if isinstance(frame, torch.Tensor) else type(frame).__name__
        raise ValueError(f"a streaming step takes one frame per sequence, shape (B, 1, ...), got {shape}; "
                         f"slice a sequence with x[:, t:t + 1]")


def _streaming_mismatch(cls: type) -> str | None:
    """Why ``cls`` may not use the streaming step it inherits, or None.

    The class that declares ``cls``'s streaming (defines ``stream_step``, or sets ``per_frame``
    for the stateless default) must be ``cls`` or a subclass of every class defining one of ``cls.stream_follows``: a
    subclass that changes ``features`` (or, for the DRF, its filter loop) without its own step
    would otherwise stream a different computation than it runs on whole sequences.
    """
    mro = cls.__mro__

    def first(names: tuple[str, ...]) -> int:
        return next((i for i, klass in enumerate(mro) if any(n in vars(klass) for n in names)), len(mro))

    stateless = cls.stream_step is SequenceModel.stream_step  # per_frame only speaks for the default step
    declared = first(("stream_step", "per_frame") if stateless else ("stream_step",))
    if mro[declared] is SequenceModel:  # nothing declared: its default step raises unless per_frame
        return None
    stale = [name for name in cls.stream_follows if first((name,)) < declared]
    if not stale:
        return None
    owner = mro[declared].__name__
    return (f"{cls.__name__} overrides {', '.join(stale)} but not its streaming step, so {owner}'s step "
            f"would stream another computation than its features: define initial_carry(frame) and "
            f"stream_step(frame, carry) for {cls.__name__}"
            + (", or set per_frame = True if it carries no state across frames" if stateless else ""))


class SequenceModel(nn.Module):
    """Shared interface (see the module docstring); subclasses define ``features``.

    Streaming: the default ``initial_carry`` / ``stream_step`` here are stateless (``features``
    of the one frame, carry None) and serve only models that declare ``per_frame = True`` (no
    recursion: NoDynamics, Monoloco); any other model raises NotImplementedError from them until
    it defines its own (DeepRecursiveFilter, LSTMBaseline). A subclass that overrides one of
    ``stream_follows`` without redefining its streaming step raises too (``_streaming_mismatch``).
    """

    kind: str = ""
    #: True: the features of frame t depend on frame t alone, and the stateless streaming step holds
    per_frame: bool = False
    #: the methods whose computation the streaming step reproduces frame by frame
    stream_follows: tuple[str, ...] = ("features",)
    _stream_error: str | None = None  # set per class by __init_subclass__

    def __init_subclass__(cls, **kwargs: Any):
        super().__init_subclass__(**kwargs)
        cls._stream_error = _streaming_mismatch(cls)

    def __init__(self, config: dict[str, Any]):
        super().__init__()
        self.config = {"kind": self.kind, **config}
        self.input_kind = config["input_kind"]
        self.out_dim = config["out_dim"]

    def features(self, inputs: torch.Tensor, return_gains: bool = False
                 ) -> tuple[torch.Tensor, torch.Tensor | None]:
        raise NotImplementedError

    def head(self, h: torch.Tensor, n_samples: int = 0, dropout_p: float | None = None
             ) -> tuple[torch.Tensor, torch.Tensor]:
        return self.decoder(h, n_samples=n_samples, dropout_p=dropout_p)

    def forward(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h, _ = self.features(inputs)
        return self.head(h)

    def loss(self, mean: torch.Tensor, sigma: torch.Tensor, targets: torch.Tensor,
             mask: torch.Tensor | None = None) -> torch.Tensor:
        return gaussian_nll(mean, sigma, targets, mask)

    @property
    def default_dropout_p(self) -> float:
        return self.decoder.dropout_p

    def kalman_gains(self, inputs: torch.Tensor) -> torch.Tensor | None:
        """Kalman gains (B, T, n, n) of the filter, None for models without one."""
        return self.features(inputs, return_gains=True)[1]

    def _check_streaming(self, frame: torch.Tensor) -> None:
        if self._stream_error:
            raise NotImplementedError(self._stream_error)
        check_frame(frame)

    def _check_per_frame(self) -> None:
        if not self.per_frame:
            raise NotImplementedError(
                f"{type(self).__name__} defines no streaming step: define initial_carry(frame) and "
                f"stream_step(frame, carry) for a model with state across frames, or set per_frame = True "
                f"if its features of a frame depend on that frame alone")

    def initial_carry(self, frame: torch.Tensor) -> Any:
        """The state carried after a sequence's first frame ``frame`` (B, 1, ...), from which
        ``stream_step`` continues. Here (per-frame models): None."""
        self._check_streaming(frame)
        self._check_per_frame()
        return None

    def stream_step(self, frame: torch.Tensor, carry: Any) -> tuple[torch.Tensor, Any]:
        """One streaming step: the deterministic features h (B, 1, D) of the next ``frame``
        (B, 1, ...) given the carried state, and the state after it.

        Stepping a sequence frame by frame from ``initial_carry`` of its first frame gives the
        same h as ``features`` on the whole sequence (tests/test_timing.py checks it). Here
        (per-frame models): ``features`` of the frame alone, carry None.
        """
        self._check_streaming(frame)
        self._check_per_frame()
        return self.features(frame)[0], None


class _EncodedSequenceModel(SequenceModel):
    """Encoder + observation heads + decoder; subclasses add the dynamics."""

    #: the features are a belief [mean, log variance] (n each), so the decoder may be split
    belief_features: bool = True

    def __init__(self, input_kind: str = "pendulum", out_dim: int = 2, latent: int = 30,
                 feature_dim: int = 64, decoder_hidden: int = 64, dropout_p: float = 0.1,
                 image_downsample: str = "pool", target_offset: float = 0.0, target_scale: float = 1.0,
                 noise_head: str = "elu", decoder_split: bool = False,
                 _extra_config: dict[str, Any] | None = None):
        if input_kind not in INPUT_KINDS:
            raise ValueError(f"input_kind must be one of {INPUT_KINDS}, got {input_kind!r}")
        for name, value in (("out_dim", out_dim), ("latent", latent), ("feature_dim", feature_dim),
                            ("decoder_hidden", decoder_hidden)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive int, got {value!r}")
        check_dropout_p(dropout_p)
        if image_downsample not in IMAGE_DOWNSAMPLES:
            raise ValueError(f"image_downsample must be one of {IMAGE_DOWNSAMPLES}, got {image_downsample!r}")
        if noise_head not in NOISE_HEADS:
            raise ValueError(f"noise_head must be one of {NOISE_HEADS}, got {noise_head!r}")
        # options of the book's protocol enter the config only when they differ from the
        # paper's, so configs (and the checkpoint names hashed from them) made before stay as they were
        if not isinstance(decoder_split, bool):
            raise ValueError(f"decoder_split must be True or False, got {decoder_split!r}")
        if decoder_split and not self.belief_features:
            raise ValueError(f"{type(self).__name__} decodes no [mean, log variance] belief, so its decoder "
                             "cannot be split (decoder_split is for the DRF and no_dynamics)")
        extra = dict(_extra_config or {}) | ({"noise_head": noise_head} if noise_head != "elu" else {}) \
            | ({"decoder_split": True} if decoder_split else {})
        super().__init__(dict(input_kind=input_kind, out_dim=out_dim, latent=latent,
                              feature_dim=feature_dim, decoder_hidden=decoder_hidden,
                              dropout_p=dropout_p, image_downsample=image_downsample,
                              target_offset=float(target_offset), target_scale=float(target_scale),
                              **extra))
        self.latent = latent
        self.encoder = make_encoder(input_kind, feature_dim, image_downsample)
        self.heads = ObservationHeads(feature_dim, latent, noise_head)
        self.decoder = Decoder(2 * latent, out_dim, decoder_hidden, dropout_p, target_offset, target_scale,
                               split=latent if decoder_split else None)

    def observe(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Encode all B*T frames in one call: w, r (B, T, n)."""
        return self.heads(self.encoder(inputs))


class NoDynamics(_EncodedSequenceModel):
    """Frame by frame: decoder([w_t, log r_t]); no state carried over time."""

    kind = "no_dynamics"
    per_frame = True

    def features(self, inputs, return_gains=False):
        w, r = self.observe(inputs)
        return mean_and_log_variance(w, r), None


class LSTMBaseline(_EncodedSequenceModel):
    """An LSTM over time on [w_t, log r_t] replaces the filter (the paper's 2nd baseline).

    Hidden size 2n (so the decoder input size matches the other models); two layers by
    default, the depth of the DRF's transition network.
    """

    belief_features = False  # its features are the LSTM's hidden state, not a [mean, log variance]

    kind = "lstm"

    def __init__(self, input_kind: str = "pendulum", out_dim: int = 2, latent: int = 30,
                 lstm_layers: int = 2, **kwargs: Any):
        if isinstance(lstm_layers, bool) or not isinstance(lstm_layers, int) or lstm_layers < 1:
            raise ValueError(f"lstm_layers must be a positive int, got {lstm_layers!r}")
        super().__init__(input_kind, out_dim, latent, _extra_config={"lstm_layers": lstm_layers},
                         **kwargs)
        self.lstm = nn.LSTM(2 * latent, 2 * latent, num_layers=lstm_layers, batch_first=True)

    def features(self, inputs, return_gains=False):
        w, r = self.observe(inputs)
        h, _ = self.lstm(mean_and_log_variance(w, r))
        return h, None

    def initial_carry(self, frame: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The LSTM's state (h_n, c_n), each (lstm_layers, B, 2n), after the first frame
        (B, 1, ...)."""
        self._check_streaming(frame)
        _, hc = self.lstm(mean_and_log_variance(*self.observe(frame)))
        return hc

    def stream_step(self, frame: torch.Tensor, carry: tuple[torch.Tensor, torch.Tensor]
                    ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
        """One LSTM step on the next frame (B, 1, ...) from the carried (h, c): the output
        h (B, 1, 2n) and the new (h_n, c_n), each (lstm_layers, B, 2n)."""
        self._check_streaming(frame)
        h, hc = self.lstm(mean_and_log_variance(*self.observe(frame)), carry)
        return h, hc


TRANSITION_KINDS = ("lstm", "basis")
# Observation variance of a memory dimension: the gain on its own (zero) observation is
# P / (P + MEMORY_VARIANCE) ~ 1e-4, i.e. unobserved up to a leak far below what training moves
# (H = [I 0] in the limit). Kept finite so the filter's Cholesky path is the same for every dim.
MEMORY_VARIANCE = 1e4


class DeepRecursiveFilter(_EncodedSequenceModel):
    """The paper's DRF: a Kalman filter on the learned latent state.

    Per sequence: w_t, r_t from the encoder for all frames at once; then for t >= 1 the
    transition network maps z_{t-1} to F_t, q_t and ``kalman_step`` gives z_t, P_t, K_t.
    The decoder reads [z_t, log diag(P_t)] (P enters through its diagonal only).

    Start: z_0 = w_0, P_0 = diag(r_0) -- the exact posterior after the first observation
    under an uninformative prior, so the gain at t = 0 is reported as I.
    The filter is causal: padding must trail a sequence's valid frames.
    In training the loop runs as one autograd node (``drfkit.models.recursion``), at
    inference step by step; both compute the same values (tests/test_recursion.py).

    Options of the book's protocol (defaults: the paper's model):
      ``transition_kind='basis'``  F_t from a softmax mixture of learned matrices on z_{t-1} alone
                                   (``drfkit.models.basis``; no memory outside the filter state)
      ``memory_dims=m``            the last m latent dims are never observed (w = 0, r =
                                   MEMORY_VARIANCE; at t = 0 the prior z = 0, P = 1): room in
                                   the state for what one frame cannot show, such as velocity
      ``noise_head='log'``         r on a bounded log scale (``ObservationHeads``)
      ``constant_q=True``          Q = diag(exp(log q)), learned, the same at every step (the LSTM
                                   transition's; the basis transition's Q is constant already)

    ``forward_with_prior`` also decodes the one-step prediction z_{t|t-1}, P_{t|t-1}, so a training
    loss can ask the transition to predict (``TrainConfig.prior_weight``).
    """

    kind = "drf"
    stream_follows = ("features", "run_filter", "filter_steps")
    #: train through the one-node recursion; False differentiates the per-step loop with autograd
    #: (same values, slower: kept for the tests and for timing the difference, not a config option)
    whole_sequence = True

    def __init__(self, input_kind: str = "pendulum", out_dim: int = 2, latent: int = 30,
                 transition_hidden: int = 64, transition_kind: str = "lstm", n_basis: int = 16,
                 memory_dims: int = 0, constant_q: bool = False, **kwargs: Any):
        if isinstance(transition_hidden, bool) or not isinstance(transition_hidden, int) \
                or transition_hidden < 1:
            raise ValueError(f"transition_hidden must be a positive int, got {transition_hidden!r}")
        if transition_kind not in TRANSITION_KINDS:
            raise ValueError(f"transition_kind must be one of {TRANSITION_KINDS}, got {transition_kind!r}")
        if isinstance(memory_dims, bool) or not isinstance(memory_dims, int) or not 0 <= memory_dims < latent:
            raise ValueError(f"memory_dims must be an int in [0, latent = {latent}), got {memory_dims!r}")
        if not isinstance(constant_q, bool):
            raise ValueError(f"constant_q must be True or False, got {constant_q!r}")
        if constant_q and transition_kind != "lstm":
            raise ValueError(f"constant_q is an option of the LSTM transition; the {transition_kind!r} "
                             "transition's Q is constant already")
        extra: dict[str, Any] = {"transition_hidden": transition_hidden}
        if transition_kind != "lstm":  # as noise_head: only what departs from the paper enters the config
            extra |= {"transition_kind": transition_kind, "n_basis": n_basis}
        if memory_dims:
            extra["memory_dims"] = memory_dims
        if constant_q:
            extra["constant_q"] = True
        super().__init__(input_kind, out_dim, latent, _extra_config=extra, **kwargs)
        self.transition_kind, self.memory_dims = transition_kind, memory_dims
        if transition_kind == "basis":
            self.transition = BasisTransition(latent, transition_hidden, n_basis)
        else:
            self.transition = TransitionNetwork(latent, transition_hidden, constant_q=constant_q)
        # the one-node recursion differentiates the LSTM transition's own q head only
        self._one_node = transition_kind == "lstm" and not constant_q

    def observe(self, inputs: torch.Tensor, starts: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
        """w, r (B, T, n); ``starts``: inputs[:, 0] is a sequence's first frame, where a memory
        dim has its prior variance 1 (False for a streaming step's later frame)."""
        w, r = super().observe(inputs)
        m = self.memory_dims
        if not m:
            return w, r
        observed = torch.arange(self.latent, device=w.device) < self.latent - m          # (n,)
        first = torch.zeros(w.shape[1], 1, dtype=torch.bool, device=w.device)
        first[0] = starts                                                                 # (T, 1)
        w = torch.where(observed, w, 0.0)
        r = torch.where(observed, r, torch.where(first, 1.0, MEMORY_VARIANCE))
        return w, r

    def run_filter(self, w: torch.Tensor, r: torch.Tensor, return_gains: bool = False,
                   whole_sequence: bool | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """Filter observations w (B, T, n) with noise variances r (B, T, n).

        Returns posterior means z (B, T, n), posterior variances diag(P) (B, T, n) and,
        if asked, the gains K (B, T, n, n) (else None). When gradients are wanted (training)
        and gains are not, the LSTM transition's recursion runs as one autograd node with a
        hand-written backward (``drfkit.models.recursion``); ``whole_sequence=False`` (default:
        the ``whole_sequence`` attribute) forces the per-step loop below, which autograd
        differentiates step by step (same values; the tests compare the two). Inference and
        the basis transition always take the per-step loop.
        """
        check_observations(w, r, self.latent)
        whole_sequence = self.whole_sequence if whole_sequence is None else whole_sequence
        if whole_sequence and self._one_node and not return_gains and torch.is_grad_enabled() and (
                w.requires_grad or r.requires_grad or any(p.requires_grad for p in self.transition.parameters())):
            z, p_diag = drf_recursion(self.transition, w, r)
            return z, p_diag, None
        trace = self.filter_steps(w, r, return_gains=return_gains)
        return trace["z"], trace["p_diag"], trace.get("gains")

    def filter_steps(self, w: torch.Tensor, r: torch.Tensor, return_gains: bool = False,
                     return_transition: bool = False, return_prior: bool = False) -> dict[str, torch.Tensor]:
        """The per-step filter loop on w, r (B, T, n), recording what was asked.

        Always: 'z', 'p_diag' (B, T, n). ``return_gains``: 'gains' K (B, T, n, n), I at t = 0.
        ``return_transition``: 'F' (B, T-1, n, n), F_t for t = 1..T-1; 'q' (B, T-1, n); 'z_prior'
        (B, T-1, n) = F_t z_{t-1}, the prediction of z_t before w_t is seen.
        ``return_prior``: 'z_prior' and 'p_prior' (B, T-1, n) = diag(F_t P_{t-1} F_t^T) + q_t, the
        prior's variances.
        """
        batch, steps, n = w.shape
        # unbind once: indexing w[:, t] in the loop would make the backward pass build
        # and sum T zero-padded (B, T, n) gradients, one per step
        w_steps, r_steps = w.unbind(1), r.unbind(1)
        z, p_diag = w_steps[0], r_steps[0]
        P = torch.diag_embed(p_diag)
        means, variances = [z], [p_diag]
        gains = [self.transition.eye.expand(batch, n, n)] if return_gains else None
        Fs, qs, priors, prior_vars = [], [], [], []
        state = self.transition.initial_state(batch, w)
        for t in range(1, steps):
            F_t, q_t, state = self.transition(z, state)
            if return_transition:
                Fs.append(F_t), qs.append(q_t)
            if return_transition or return_prior:
                priors.append((F_t @ z.unsqueeze(-1)).squeeze(-1))
            if return_prior:  # diag(F P F^T) without forming the product
                prior_vars.append(torch.einsum("bij,bjk,bik->bi", F_t, P, F_t) + q_t)
            z, P, K = kalman_step(z, P, F_t, q_t, w_steps[t], r_steps[t])
            means.append(z)
            variances.append(P.diagonal(dim1=-2, dim2=-1))
            if gains is not None:
                gains.append(K)
        out = {"z": torch.stack(means, dim=1), "p_diag": torch.stack(variances, dim=1)}
        if gains is not None:
            out["gains"] = torch.stack(gains, dim=1)
        empty = w.new_empty(batch, 0, n)
        if return_transition:
            out["F"] = torch.stack(Fs, dim=1) if Fs else w.new_empty(batch, 0, n, n)
            out["q"] = torch.stack(qs, dim=1) if qs else empty
        if return_transition or return_prior:
            out["z_prior"] = torch.stack(priors, dim=1) if priors else empty
        if return_prior:
            out["p_prior"] = torch.stack(prior_vars, dim=1) if prior_vars else empty
        return out

    def forward_with_prior(self, inputs: torch.Tensor
                           ) -> tuple[tuple[torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor]]:
        """(mean, sigma) (B, T, out) of the posterior, as ``forward``, and (mean, sigma) (B, T-1, out)
        decoded by the same decoder from the one-step prior [z_{t|t-1}, log diag P_{t|t-1}],
        t = 1..T-1: what the filter expects of frame t before seeing it. Per-step loop."""
        trace = self.filter_steps(*self.observe(inputs), return_prior=True)
        posterior = self.head(mean_and_log_variance(trace["z"], trace["p_diag"]))
        prior = self.head(mean_and_log_variance(trace["z_prior"], trace["p_prior"]))
        return posterior, prior

    def features(self, inputs, return_gains=False):
        w, r = self.observe(inputs)
        z, p_diag, gains = self.run_filter(w, r, return_gains)
        return mean_and_log_variance(z, p_diag), gains

    def initial_carry(self, frame: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, tuple]:
        """The filter's state after the first frame (B, 1, ...): z_0 = w_0 (B, n),
        P_0 = diag(r_0) (B, n, n) and the transition's initial state -- exactly what
        ``filter_steps`` starts from."""
        self._check_streaming(frame)
        w, r = self.observe(frame)
        z, p_diag = w[:, 0], r[:, 0]
        return z, torch.diag_embed(p_diag), self.transition.initial_state(z.shape[0], z)

    def stream_step(self, frame: torch.Tensor, carry: tuple[torch.Tensor, torch.Tensor, tuple]
                    ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor, tuple]]:
        """One filter step on the next frame (B, 1, ...) from the carried (z, P, state) of the
        previous one: encoder, transition F_t, q_t from z_{t-1}, Kalman predict/update with
        w_t, r_t. Returns h = [z_t, log diag P_t] (B, 1, 2n) and (z_t (B, n), P_t (B, n, n),
        the transition's state)."""
        self._check_streaming(frame)
        z, P, state = carry
        w, r = self.observe(frame, starts=False)
        F_t, q_t, state = self.transition(z, state)
        z, P, _ = kalman_step(z, P, F_t, q_t, w[:, 0], r[:, 0])
        h = mean_and_log_variance(z, P.diagonal(dim1=-2, dim2=-1)).unsqueeze(1)
        return h, (z, P, state)
