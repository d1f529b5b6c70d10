"""What a process fixes before it computes anything: torch threads, deterministic algorithms,
seeds and the device. Only torch, numpy and the standard library: every entry point (a notebook
through ``drfkit.book.runtime``, ``python -m drfkit train``, a grid worker) may use it."""
from __future__ import annotations

import os
import random

import numpy as np
import torch


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


def pick_device(device: str) -> torch.device:
    """'auto' uses CUDA when present; 'cuda' without CUDA is an error, never a silent CPU run."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if device == "cuda" and not torch.cuda.is_available():
        raise RuntimeError("device 'cuda' was asked for but torch sees no GPU; use device: auto or cpu")
    return torch.device(device)


def setup(threads: int, seed: int, device: str) -> torch.device:
    """Threads, deterministic algorithms, seeds and the device: what every entry point
    (a notebook, ``python -m drfkit train``) fixes before it computes anything."""
    if threads:
        torch.set_num_threads(threads)
    # cuBLAS is only deterministic with a fixed workspace; must be set before its first call
    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    torch.use_deterministic_algorithms(True, warn_only=True)
    seed_everything(seed)
    return pick_device(device)  # fail now, not after an hour of CPU training


__all__ = ["seed_everything", "pick_device", "setup"]
