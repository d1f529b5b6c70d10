"""``SequenceData``: the one container every study's splits come in, and every model trains and is judged on."""
from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass
class SequenceData:
    """A data set of sequences, as tensors.

    inputs:  (N, T, ...) uint8 images (N, T, 24, 24) or float keypoints (N, T, 17, 3)
    targets: (N, T, out) float32
    mask:    (N, T) bool, True on real frames (False on padding); None = all real
    """

    inputs: torch.Tensor
    targets: torch.Tensor
    mask: torch.Tensor | None = None

    def __post_init__(self) -> None:
        self.inputs = torch.as_tensor(self.inputs)
        self.targets = torch.as_tensor(self.targets, dtype=torch.float32)
        if self.targets.ndim == 2:
            self.targets = self.targets.unsqueeze(-1)
        if self.mask is not None:
            self.mask = torch.as_tensor(self.mask, dtype=torch.bool)
        n, t = self.targets.shape[:2]
        if len(self) == 0:
            raise ValueError("empty data set: no sequences to train or evaluate on")
        if self.inputs.shape[:2] != (n, t):
            raise ValueError(f"inputs {tuple(self.inputs.shape)} and targets {tuple(self.targets.shape)} "
                             "disagree on (N, T)")
        if self.mask is not None and self.mask.shape != (n, t):
            raise ValueError(f"mask {tuple(self.mask.shape)} must be (N, T) = {(n, t)}")
        if self.inputs.is_floating_point() and not torch.isfinite(self.inputs).all():
            raise ValueError("inputs contain NaN or inf; zero missing keypoints with confidence 0 instead")
        if not torch.isfinite(self.targets).all():
            raise ValueError("targets contain NaN or inf")

    def __len__(self) -> int:
        return self.targets.shape[0]

    def frames(self) -> "SequenceData":
        """Every real frame as its own length-1 sequence (for single-frame models)."""
        keep = self.mask.reshape(-1) if self.mask is not None else slice(None)
        flat = lambda x: x.reshape(-1, 1, *x.shape[2:])[keep]  # noqa: E731
        return SequenceData(flat(self.inputs), flat(self.targets), None)

    def batch(self, idx: torch.Tensor, device: torch.device):
        mask = None if self.mask is None else self.mask[idx].to(device)
        return self.inputs[idx].to(device), self.targets[idx].to(device), mask


__all__ = ["SequenceData"]
