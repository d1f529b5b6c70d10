"""The DRF family's interface and baselines: NoDynamics and LSTMBaseline here, DeepRecursiveFilter
in ``drfkit.models.drf``.

All three share the encoder, the observation heads and the decoder; they differ only in
what sits between the heads and the decoder. Every model (Monoloco included) exposes
the same interface, which the training loop, ``drfkit.methods.uncertainty`` and the timing code
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

Capabilities a model class declares, so that code outside ``drfkit.models`` asks the model, never
its kind (a model added in one file declares what it has):

    competency_gain = True       its ``kalman_gains`` are square gains on its state whose diagonal
                                 says how much a frame's observation moves the belief, so that
                                 Kalman-gain gating (``drfkit.methods.gating``) scores competency
                                 on them (the DRF; the known-dynamics filter has gains too, but
                                 state x observation ones, and is not gated)
    model.one_node_recursion(w, r), model.recursion_weights()
                                 its filter recursion on observations w, r as one autograd node,
                                 and the weights it reads: what
                                 ``drfkit.methods.timing.recursion_scaling`` times apart from the
                                 training step (the DRF; None elsewhere)

Training schedules are not the models' business: ``drfkit.study.studies.train_config`` holds them.

Inputs: 'pendulum' uint8 images (B, T, 24, 24); 'keypoints' float32 (B, T, 17, 3).
Outputs: pendulum (B, T, 2) = (cos theta, sin theta); pedestrians (B, T, 1) depth (m).
"""
from __future__ import annotations

import math
from typing import Any

import torch
from torch import nn

from drfkit.models.parts import (IMAGE_DOWNSAMPLES, LOG_R_RANGE, NOISE_HEADS, OUTPUT_LOG_R_RANGE, SIGMA_FLOOR, Decoder, ImageEncoder, KeypointEncoder,
                                 ObservationHeads, SharedUniforms, check_dropout_p, check_n_samples,
                                 mean_and_log_variance)
from drfkit.models.spec import ModelSpec

INPUT_KINDS = ("pendulum", "keypoints")
# how a belief [mean, log variance] becomes the output: the learned decoder (MC dropout), or read as it is
# (the first out_dim latent dims are the output's units, so r and q are variances of the output)
READOUTS = ("decoder", "identity")
KEYPOINT_HIDDEN = 128  # the keypoint encoder's hidden width (``encoder_hidden``)

_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)


def make_encoder(input_kind: str, feature_dim: int, image_downsample: str, channels: int = 12,
                 hidden: int = KEYPOINT_HIDDEN) -> nn.Module:
    if input_kind == "pendulum":
        return ImageEncoder(feature_dim, channels=channels, downsample=image_downsample)
    if input_kind == "keypoints":
        return KeypointEncoder(feature_dim, hidden=hidden)
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
    #: True: ``kalman_gains`` are square gains on the state whose diagonal scores competency, and
    #: Kalman-gain gating (``drfkit.methods.gating``) runs on this model (module docstring)
    competency_gain: bool = False
    #: a model whose filter recursion runs as one autograd node defines ``one_node_recursion(w, r)`` and
    #: ``recursion_weights()`` (``drfkit.models.drf``); None: it has no such recursion to time
    one_node_recursion = None
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

    def head(self, h: torch.Tensor, n_samples: int = 0, dropout_p: float | None = None,
             uniforms: SharedUniforms | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        return self.decoder(h, n_samples=n_samples, dropout_p=dropout_p, uniforms=uniforms)

    def forward(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h, _ = self.features(inputs)
        return self.head(h)

    def regulariser(self) -> torch.Tensor | float:
        """A term the model adds to its training loss (``drfkit.methods.objectives.batch_loss``); none here."""
        return 0.0

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
                 noise_head: str = "elu", decoder_split: bool = False, encoder_channels: int = 12,
                 readout: str = "decoder", encoder_hidden: int = KEYPOINT_HIDDEN,
                 _extra_config: dict[str, Any] | None = None):
        if input_kind not in INPUT_KINDS:
            raise ValueError(f"input_kind must be one of {INPUT_KINDS}, got {input_kind!r}")
        for name, value in (("out_dim", out_dim), ("latent", latent), ("feature_dim", feature_dim),
                            ("decoder_hidden", decoder_hidden), ("encoder_channels", encoder_channels),
                            ("encoder_hidden", encoder_hidden)):
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
        if readout not in READOUTS:
            raise ValueError(f"readout must be one of {READOUTS}, got {readout!r}")
        if encoder_hidden != KEYPOINT_HIDDEN and input_kind != "keypoints":
            raise ValueError(f"encoder_hidden is the keypoint encoder's width; the image encoder's is "
                             f"encoder_channels (got encoder_hidden={encoder_hidden!r} for {input_kind!r})")
        if readout == "identity" and (not self.belief_features or decoder_split):
            raise ValueError("readout='identity' reads the output off the belief's first out_dim dims: for the DRF "
                             "and no_dynamics, without decoder_split")
        extra = dict(_extra_config or {}) | ({"noise_head": noise_head} if noise_head != "elu" else {}) \
            | ({"readout": readout} if readout != "decoder" else {}) \
            | ({"decoder_split": True} if decoder_split else {}) \
            | ({"encoder_channels": encoder_channels} if encoder_channels != 12 else {}) \
            | ({"encoder_hidden": encoder_hidden} if encoder_hidden != KEYPOINT_HIDDEN else {})
        super().__init__(dict(input_kind=input_kind, out_dim=out_dim, latent=latent,
                              feature_dim=feature_dim, decoder_hidden=decoder_hidden,
                              dropout_p=dropout_p, image_downsample=image_downsample,
                              target_offset=float(target_offset), target_scale=float(target_scale),
                              **extra))
        self.latent, self.readout = latent, readout
        self.encoder = make_encoder(input_kind, feature_dim, image_downsample, encoder_channels, encoder_hidden)
        self.heads = ObservationHeads(feature_dim, latent, noise_head, normalise=readout == "decoder",
                                      log_r_range=LOG_R_RANGE if readout == "decoder" else OUTPUT_LOG_R_RANGE)
        self.decoder = Decoder(2 * latent, out_dim, decoder_hidden, dropout_p, target_offset, target_scale,
                               split=latent if decoder_split else None) if readout == "decoder" else None

    def head(self, h: torch.Tensor, n_samples: int = 0, dropout_p: float | None = None,
             uniforms: SharedUniforms | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """The decoder's (mean, sigma); with ``readout='identity'`` the belief read as it is: mean =
        its first out_dim dims, sigma = the square root of their variances (+ SIGMA_FLOOR), no dropout
        (S identical samples: no epistemic spread)."""
        if self.readout == "decoder":
            return self.decoder(h, n_samples=n_samples, dropout_p=dropout_p, uniforms=uniforms)
        check_n_samples(n_samples)
        k = self.out_dim
        mean = h[..., :k]
        sigma = torch.exp(0.5 * h[..., self.latent:self.latent + k]) + SIGMA_FLOOR
        if n_samples:
            return mean.expand(n_samples, *mean.shape), sigma.expand(n_samples, *sigma.shape)
        return mean, sigma

    @property
    def default_dropout_p(self) -> float:
        return self.decoder.dropout_p if self.decoder is not None else 0.0

    def observe(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Encode all B*T frames in one call: w, r (B, T, n)."""
        return self.heads(self.encoder(inputs))

    def observation_output(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(mean, sigma) (B, T, out) decoded from the observation alone, [w_t, log r_t]: what an
        observation loss fits (``TrainConfig.obs_weight``), so that r_t is trained as the variance of
        what frame t shows. With the split decoder, that decode's sigma comes from r_t alone."""
        if not self.belief_features:
            raise ValueError(f"{type(self).__name__} decodes no [mean, log variance] belief, so it has no "
                             "observation to decode; set obs_weight = 0 for it")
        w, r = _EncodedSequenceModel.observe(self, inputs)
        return self.head(mean_and_log_variance(w, r))


class NoDynamics(_EncodedSequenceModel):
    """Frame by frame: decoder([w_t, log r_t]); no state carried over time."""

    kind = "no_dynamics"
    spec = ModelSpec("No dynamics", "tab:red", studies=("pendulum", "pedestrians"),
                     protocols={"paper": "no_dynamics_paper", "book": "fit_no_dynamics_wide"})
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
    spec = ModelSpec("LSTM", "tab:green", studies=("pendulum", "pedestrians"),
                     protocols={"paper": "lstm_paper", "book": "fit_lstm_wide"})

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
