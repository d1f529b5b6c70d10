"""The building blocks shared by every model of the DRF family.

encoder (image or keypoints) -> ObservationHeads (w, r) -> dynamics (none / LSTM /
recursive filter) -> Decoder (mean, sigma, MC dropout).

Shapes: B batch, T time, N = B*T frames, n latent size, S Monte Carlo samples.
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

# ELU(x) + 1 tends to 0 for very negative x; a variance of exactly 0 would make the
# Kalman innovation covariance singular, so observation and process variances get this
# floor (the paper has none; it is far below any variance a trained model emits).
VARIANCE_FLOOR = 1e-4

# The paper's sigma head is ELU + 1 >= 0; the Gaussian NLL needs sigma > 0, so the
# decoder adds this floor (in output units: radians-ish on the pendulum, metres on
# pedestrians). It only matters for a head pushed far negative.
SIGMA_FLOOR = 1e-3

PENDULUM_SIZE = 24
# Frames per encoder call. A training batch of 50 sequences x 75 frames makes 100 MB
# activations per conv layer; cut into chunks of this size they stay in cache, and the
# encoder's forward + backward runs ~1.5x faster on one CPU core (measured, 3750 frames:
# 1.17 s whole, 0.77 s in chunks of 256). The function computed is the same.
ENCODER_CHUNK_FRAMES = 256
# oneDNN convolves a batch of very few frames with other kernels, which round differently: a frame's code changed in
# the last bit in batches of 1-3 frames at one thread and of 1-11 frames (not multiples of 4) at two (measured on
# the AMD EPYC; 4-256 frames at one thread gave the 256-frame batch's codes bit for bit). The distinct-frames path,
# which gathers codes computed in other calls, pads a smaller chunk to this many frames.
MIN_CODE_CHUNK = 32
IMAGE_DOWNSAMPLES = ("pool", "stride")
N_KEYPOINTS = 17


def positive_elu(x: torch.Tensor, floor: float) -> torch.Tensor:
    """ELU(x) + 1 + floor: the paper's positive head, kept strictly above ``floor``."""
    return F.elu(x) + (1.0 + floor)


def fold_time(x: torch.Tensor, n_trailing: int) -> tuple[torch.Tensor, tuple[int, ...]]:
    """(B, T, *rest) -> (B*T, *rest), returning (B, T) to unfold later."""
    lead = tuple(x.shape[: x.ndim - n_trailing])
    return x.reshape(-1, *x.shape[x.ndim - n_trailing:]), lead


class ImageEncoder(nn.Module):
    """Pendulum frames (B, T, 24, 24) uint8 -> features (B, T, feature_dim).

    The paper: a 5x5 conv, a 3x3 conv, then a fully connected layer. Ours, as the
    Recurrent Kalman Network's pendulum encoder: conv5x5(12) -> maxpool2 -> ReLU ->
    conv3x3(12) -> maxpool2 -> ReLU -> flatten (12*6*6) -> Linear -> ReLU. (Pooling
    before the ReLU is the same function -- ReLU is monotone -- on 4x fewer values.)
    ``downsample='stride'`` replaces the first pooling by a stride-2 5x5 conv: the
    encoder's forward+backward is ~2.5x cheaper on CPU, at the cost of departing from
    the RKN layout. The B*T frames go through in chunks of ``ENCODER_CHUNK_FRAMES``.
    """

    def __init__(self, feature_dim: int = 64, channels: int = 12, downsample: str = "pool"):
        super().__init__()
        if downsample not in IMAGE_DOWNSAMPLES:
            raise ValueError(f"downsample must be one of {IMAGE_DOWNSAMPLES}, got {downsample!r}")
        self.first_stride = 2 if downsample == "stride" else 1
        self.conv1 = nn.Conv2d(1, channels, kernel_size=5, padding=2, stride=self.first_stride)
        self.conv2 = nn.Conv2d(channels, channels, kernel_size=3, padding=1)
        self.fc = nn.Linear(channels * (PENDULUM_SIZE // 4) ** 2, feature_dim)
        self.out_dim = feature_dim
        self.distinct_frames = False  # True for a block of inference: ``distinct_frames_once``
        self.frame_codes = None  # that block's book of the codes computed (``drfkit.models.frame_codes``)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        if images.ndim != 4 or images.shape[-2:] != (PENDULUM_SIZE, PENDULUM_SIZE):
            raise ValueError(f"pendulum images must have shape (B, T, 24, 24), got {tuple(images.shape)}")
        frames, (b, t) = fold_time(images, 2)  # (N, 24, 24)
        if frames.dtype == torch.uint8:
            if self.distinct_frames and not torch.is_grad_enabled():
                # each distinct frame once: the bytes' rows made unique (0.2 s for 38,400 frames on a CPU core),
                # and of those only the ones the block has not encoded yet (``FrameCodes``)
                distinct, index = torch.unique(frames.flatten(1), dim=0, return_inverse=True)  # (M, 576), (N,)
                codes = (self.frame_codes.codes_of(distinct, self._encode_rows) if self.frame_codes is not None
                         else self._encode_rows(distinct))  # (M, feature_dim)
                return codes[index].view(b, t, -1)
            x = frames.to(self.fc.weight.dtype) / 255.0
        elif frames.is_floating_point():
            # Floats are taken as already scaled to [0, 1]; 0..255 floats would train on
            # saturated inputs without complaint, so reject them here.
            if frames.numel() and float(frames.detach().abs().max()) > 1.5:
                raise ValueError("float pendulum images must be scaled to [0, 1]; pass uint8 0..255 "
                                 "images (they are divided by 255 here) or divide by 255 first")
            x = frames.to(self.fc.weight.dtype)
        else:
            raise TypeError(f"pendulum images must be uint8 (or float in [0, 1]), got {images.dtype}")
        return self._encode_float(x).view(b, t, -1)

    def _encode_rows(self, rows: torch.Tensor) -> torch.Tensor:
        """(M, 576) uint8 frames as rows -> (M, feature_dim), each chunk padded to ``MIN_CODE_CHUNK`` frames: the
        codes of the distinct-frames path are gathered across calls, so a frame's code must not depend on how
        many frames came with it."""
        x = rows.view(-1, PENDULUM_SIZE, PENDULUM_SIZE).to(self.fc.weight.dtype) / 255.0
        codes = []
        for chunk in x.split(ENCODER_CHUNK_FRAMES):
            n = chunk.shape[0]
            if n < MIN_CODE_CHUNK:  # copies of its first frame: the large-batch kernels, thrown away after
                chunk = torch.cat([chunk, chunk[:1].expand(MIN_CODE_CHUNK - n, -1, -1)])
            codes.append(self.encode_frames(chunk)[:n])
        return torch.cat(codes) if codes else x.new_zeros((0, self.out_dim))

    def _encode_float(self, x: torch.Tensor) -> torch.Tensor:
        """(N, 24, 24) frames in [0, 1] -> (N, feature_dim), in chunks of ``ENCODER_CHUNK_FRAMES``."""
        if not x.shape[0]:
            return x.new_zeros((0, self.out_dim))
        return torch.cat([self.encode_frames(chunk) for chunk in x.split(ENCODER_CHUNK_FRAMES)])

    def encode_frames(self, frames: torch.Tensor) -> torch.Tensor:
        """(N, 24, 24) float frames -> (N, feature_dim)."""
        x = self.conv1(frames.unsqueeze(1))
        x = F.relu(max_pool_2x2(x) if self.first_stride == 1 else x)
        x = F.relu(max_pool_2x2(self.conv2(x)))
        return F.relu(self.fc(x.flatten(1)))


def max_pool_2x2(x: torch.Tensor) -> torch.Tensor:
    """``F.max_pool2d(x, 2)`` of (N, C, H, W), H and W even. Without autograd, as two elementwise maxima
    of strided halves: the same values bit for bit, 10-20x faster on CPU (one thread, 256 frames of
    12 x 24 x 24: 16.9 ms against 1.3 ms), which makes evaluation's encoder ~2.5x faster. With autograd,
    max_pool2d itself: torch.maximum splits a tie's gradient where max_pool2d gives it to one input, and
    training keeps the rule its checkpoints were trained with."""
    if torch.is_grad_enabled() and x.requires_grad:
        return F.max_pool2d(x, 2)
    rows = torch.maximum(x[..., 0::2, :], x[..., 1::2, :])
    return torch.maximum(rows[..., 0::2], rows[..., 1::2])


class KeypointEncoder(nn.Module):
    """Keypoints (B, T, 17, 3) = (x, y, confidence) -> features (B, T, feature_dim).

    The paper concatenates the 17x2 keypoints and the 17 confidences. We present the same
    numbers as Monoloco does -- (x, y) relative to the centre of the keypoints' box, which
    carries the person's apparent size, hence depth -- plus that centre (where in the image
    the person is) and the confidences: 34 + 2 + 17 = 53 inputs, Linear -> ReLU -> Linear ->
    ReLU. Raw coordinates would make the network learn the subtraction itself.
    """

    def __init__(self, feature_dim: int = 64, hidden: int = 128):
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(KEYPOINT_FEATURES, hidden), nn.ReLU(),
            nn.Linear(hidden, feature_dim), nn.ReLU(),
        )
        self.out_dim = feature_dim

    def forward(self, keypoints: torch.Tensor) -> torch.Tensor:
        check_keypoints(keypoints)  # before the cast: integer keypoints are an error, not a conversion
        return self.net(keypoint_features(keypoints.to(self.net[0].weight.dtype)))


KEYPOINT_FEATURES = N_KEYPOINTS * 3 + 2  # 34 centred (x, y) + the box centre + 17 confidences


def keypoint_features(keypoints: torch.Tensor) -> torch.Tensor:
    """(B, T, 17, 3) -> (B, T, 53): what the DRF family's encoder reads -- the detected keypoints'
    (x, y) relative to the centre of their box (missed ones 0), that centre, and the 17 confidences.
    Layout: x0, y0, ..., x16, y16, centre x, centre y, c0, ..., c16."""
    check_keypoints(keypoints)
    centre, centred = keypoint_box_centre(keypoints)  # (B, T, 1, 2), (B, T, 17, 2)
    return torch.cat([centred.flatten(-2), centre.flatten(-2), keypoints[..., 2]], dim=-1)


def keypoint_box_centre(keypoints: torch.Tensor, include_missed: bool = False
                        ) -> tuple[torch.Tensor, torch.Tensor]:
    """(..., 17, 3) -> centre (..., 1, 2) of the bounding box of the keypoints and their
    (x, y) relative to it (..., 17, 2).

    ``include_missed=False`` (the DRF family's encoder): the box of the detected keypoints
    (confidence > 0); missed ones are set to 0 (the box centre) instead of landing at minus the
    centre, and a frame with no keypoint is all 0. ``include_missed=True`` (Monoloco as
    published): the box of all 17, missed keypoints' placeholders included, every one centred.
    """
    xy = keypoints[..., :2]
    if include_missed:
        centre = 0.5 * (xy.amin(dim=-2, keepdim=True) + xy.amax(dim=-2, keepdim=True))
        return centre, xy - centre
    seen = (keypoints[..., 2] > 0).unsqueeze(-1)  # (..., 17, 1)
    big = torch.finfo(xy.dtype).max
    lo = torch.where(seen, xy, big).amin(dim=-2, keepdim=True)
    hi = torch.where(seen, xy, -big).amax(dim=-2, keepdim=True)
    any_seen = seen.any(dim=-2, keepdim=True)
    centre = torch.where(any_seen, 0.5 * (lo + hi), 0.0)
    return centre, torch.where(seen, xy - centre, 0.0)


def check_keypoints(keypoints: torch.Tensor) -> None:
    if keypoints.ndim != 4 or keypoints.shape[-2:] != (N_KEYPOINTS, 3):
        raise ValueError(f"keypoints must have shape (B, T, 17, 3), got {tuple(keypoints.shape)}")
    if not keypoints.is_floating_point():
        raise TypeError(f"keypoints must be float32 (x, y, confidence), got {keypoints.dtype}")


# The bounded log-variance head's range: r in [1e-3, 1e3] around the start r = 1. Six decades
# let r follow frame quality from a sharp frame (gain near 1) to pure noise (gain near 0); the
# paper's ELU + 1 head grows only linearly, so reaching r = 1e3 needs weights 1000x the start.
LOG_R_RANGE = (math.log(1e-3), math.log(1e3))
# r of an observation in the output's own units (cos, sin): from a sharp frame's ~(0.003)^2 to pure noise's
# spread over the unit circle (the known-dynamics filter's, and the DRF's with readout='identity')
OUTPUT_LOG_R_RANGE = (math.log(1e-6), math.log(1e1))
NOISE_HEADS = ("elu", "log", "quality")


class ObservationHeads(nn.Module):
    """Features (..., D) -> latent observation w (..., n) and the diagonal r of R (..., n).

    w = LayerNorm(Linear1(x));
    r = ELU(Linear2(x)) + 1 (+ VARIANCE_FLOOR)              ``noise_head='elu'`` (the paper's), or
    log r = lo + (hi - lo) * sigmoid(Linear2(x))             ``noise_head='log'``, (lo, hi) = LOG_R_RANGE, or
    log r_i = lo + (hi - lo) * sigmoid(a_i + softplus(b_i) s) ``noise_head='quality'``: one learned score
        s = Linear2(x) (..., 1) per frame, a monotone link to every dim's r (a frame judged worse raises
        every r_i, so the gain can only fall together on it).
    """

    def __init__(self, in_dim: int, latent: int = 30, noise_head: str = "elu", normalise: bool = True,
                 log_r_range: tuple[float, float] = LOG_R_RANGE):
        super().__init__()
        if noise_head not in NOISE_HEADS:
            raise ValueError(f"noise_head must be one of {NOISE_HEADS}, got {noise_head!r}")
        self.noise_head, self.log_r_range = noise_head, log_r_range
        self.linear1 = nn.Linear(in_dim, latent)
        # w in the units of the outputs (identity readout) must not be normalised
        self.norm = nn.LayerNorm(latent) if normalise else nn.Identity()
        self.linear2 = nn.Linear(in_dim, 1 if noise_head == "quality" else latent)
        if noise_head == "quality":
            self.quality_offset = nn.Parameter(torch.zeros(latent))
            self.quality_slope = nn.Parameter(torch.zeros(latent))

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        pre = self.linear2(x)
        if self.noise_head == "quality":
            lo, hi = self.log_r_range
            r = torch.exp(lo + (hi - lo) * torch.sigmoid(self.quality_offset + F.softplus(self.quality_slope) * pre))
        elif self.noise_head == "log":
            lo, hi = self.log_r_range
            r = torch.exp(lo + (hi - lo) * torch.sigmoid(pre))
        else:
            r = positive_elu(pre, VARIANCE_FLOOR)
        return self.norm(self.linear1(x)), r


def mean_and_log_variance(mean: torch.Tensor, variance: torch.Tensor) -> torch.Tensor:
    """[mean, log variance] (..., 2n): how a Gaussian belief enters the decoder / LSTM.

    Variances span orders of magnitude (the filter shrinks P, the encoder can push r
    high on noisy frames); the log puts them on the scale of the LayerNorm-ed means.
    """
    return torch.cat([mean, torch.log(variance)], dim=-1)


class Decoder(nn.Module):
    """x (..., in_dim) -> mean (..., out_dim), sigma (..., out_dim), with MC dropout.

    h = ReLU(Linear3(x)); dropout(h); mean = Linear4(h); sigma = ELU(Linear5(h)) + 1
    (+ SIGMA_FLOOR). Only the dropout is random, so for Monte Carlo sampling h is
    computed once and S dropout masks are applied in one batched op.

    ``target_offset`` and ``target_scale`` (fixed, from the training targets) put the
    outputs in target units: mean = offset + scale * Linear4(h), sigma = scale * (...).
    The network then works in standardised units -- depths of 5-50 m would otherwise
    take a 1e-4 learning rate many epochs just to reach their mean. Identity by default.
    """

    def __init__(self, in_dim: int, out_dim: int, hidden: int = 64, dropout_p: float = 0.1,
                 target_offset: float = 0.0, target_scale: float = 1.0, split: int | None = None):
        super().__init__()
        check_dropout_p(dropout_p)
        if not target_scale > 0:
            raise ValueError(f"target_scale must be > 0, got {target_scale!r}")
        if split is not None and not 0 < split < in_dim:
            raise ValueError(f"split must lie in (0, {in_dim}) (the inputs that feed the mean), got {split!r}")
        # split: the mean reads x[..., :split] alone (a belief's mean), sigma x[..., split:] alone (its
        # log variance), each through its own hidden layer; so sigma can only come from the variance
        self.split, self.hidden_dim = split, hidden
        self.linear3 = nn.Linear(in_dim if split is None else split, hidden)
        if split is not None:
            self.linear3_sigma = nn.Linear(in_dim - split, hidden)
        self.linear4 = nn.Linear(hidden, out_dim)
        self.linear5 = nn.Linear(hidden, out_dim)
        self.dropout_p = float(dropout_p)
        self.target_offset, self.target_scale = float(target_offset), float(target_scale)

    def hidden(self, x: torch.Tensor) -> torch.Tensor:
        """The deterministic part: ReLU(Linear3(x)) (..., hidden); split: the mean's and sigma's
        hidden layers side by side (..., 2 hidden)."""
        if self.split is None:
            return F.relu(self.linear3(x))
        return torch.cat([F.relu(self.linear3(x[..., :self.split])),
                          F.relu(self.linear3_sigma(x[..., self.split:]))], dim=-1)

    def readout(self, h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(Dropped-out) hidden (..., hidden) -> mean, sigma (..., out_dim)."""
        if self.split is None:
            mean, sigma = self.linear4(h), positive_elu(self.linear5(h), SIGMA_FLOOR)
        else:
            k = self.hidden_dim
            mean, sigma = self.linear4(h[..., :k]), positive_elu(self.linear5(h[..., k:]), SIGMA_FLOOR)
        if self.target_scale == 1.0 and self.target_offset == 0.0:
            return mean, sigma
        return self.target_offset + self.target_scale * mean, self.target_scale * sigma

    def forward(self, x: torch.Tensor, n_samples: int = 0, dropout_p: float | None = None,
                uniforms: SharedUniforms | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """n_samples = 0: one pass, dropout as nn.Dropout (on in train mode only), shapes
        (..., out_dim). n_samples = S > 0: S passes with dropout ON at rate ``dropout_p``
        (default: the module's rate) whatever the mode, shapes (S, ..., out_dim); ``uniforms``
        shares the masks' draws across rates (``SharedUniforms``).
        """
        check_n_samples(n_samples)
        p = self.dropout_p if dropout_p is None else check_dropout_p(dropout_p)
        h = self.hidden(x)
        if n_samples == 0:
            return self.readout(F.dropout(h, p, training=self.training))
        return self.readout(mc_dropout(h, n_samples, p, uniforms))


class SharedUniforms:
    """The U(0, 1) draws of Monte Carlo dropout, shared by the passes at several dropout rates.

    A unit is kept at rate p when its U >= p: Bernoulli(1 - p), as dropout's. One draw per shape
    serves every rate (the masks are nested: common random numbers across the rates of a PICP-MPIW
    curve), so five rates cost one draw instead of five; ``mc_dropout`` without one draws afresh."""

    def __init__(self):
        self._draws: dict[tuple, torch.Tensor] = {}

    def draw(self, shape: tuple[int, ...], like: torch.Tensor) -> torch.Tensor:
        key = (tuple(shape), like.dtype, like.device)
        if key not in self._draws:
            self._draws[key] = torch.rand(shape, dtype=like.dtype, device=like.device)
        return self._draws[key]


def mc_dropout(h: torch.Tensor, n_samples: int, p: float, uniforms: SharedUniforms | None = None) -> torch.Tensor:
    """S inverted-dropout copies of h (...): (S, ...), unit kept where U >= p, U ~ U(0, 1) of shape
    (S, ...) from torch's default generator (or ``uniforms``' shared draw). A uniform draw and a
    comparison is ~1.6x faster than ``bernoulli_`` on CPU. With p = 0 the copies are exact (an
    expand, no arithmetic), so their spread is 0.
    """
    if p == 0.0:
        return h.unsqueeze(0).expand(n_samples, *h.shape)
    shape = (n_samples, *h.shape)
    u = torch.rand(shape, dtype=h.dtype, device=h.device) if uniforms is None else uniforms.draw(shape, h)
    return (u >= p).to(h.dtype).mul_(h * (1.0 / (1.0 - p)))


def check_n_samples(n_samples) -> int:
    if isinstance(n_samples, bool) or not isinstance(n_samples, int) or n_samples < 0:
        raise ValueError(f"n_samples must be an int >= 0 (0 = one deterministic pass), got {n_samples!r}")
    return n_samples


def check_dropout_p(p) -> float:
    if isinstance(p, bool) or not isinstance(p, (int, float)) or not 0.0 <= float(p) < 1.0:
        raise ValueError(f"dropout_p must be a number in [0, 1), got {p!r}")
    return float(p)
