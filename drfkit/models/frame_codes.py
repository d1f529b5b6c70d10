"""Evaluation's image encoders on distinct frames: ``distinct_frames_once`` and the codes an encoder has computed
for distinct uint8 frames within one such block (``FrameCodes``).

``distinct_frames_once`` opens a ``FrameCodes`` book for its outermost block: every call inside the block
encodes only the frames the block has not seen yet and gathers the others from the book. One task of the
dissection or of the mechanism checks passes a model over several sets made from the same test sequences -- at
the training noise, its blackout version (frames [30, 45) pure noise, every other frame the same bytes) and the
noiseless frames -- so the blackout set costs the encoder its 15 gap frames, not 75, and a second pass over a set
costs nothing. The encoder pads a small chunk (``parts.MIN_CODE_CHUNK``), and then a frame's code does not depend
on the other frames of its chunk (tested), so the numbers are the same bit for bit. The book lives for the block
only; a change of the encoder's weights inside it empties it. (This module sits above ``parts``: the models import
``parts``, and only evaluation code imports this.)

Lookup: each frame's 576 bytes are hashed to one int64 key (a fixed random linear map, wrapping arithmetic),
keys are matched by a sorted search, and every match is checked byte for byte, so a hash collision can only cost
an encoder pass, never return another frame's code.
"""
from __future__ import annotations

import contextlib
from typing import Callable, Iterator

import torch
from torch import nn

from drfkit.models.parts import ImageEncoder

_KEY_SEED = 20240406  # the hash's fixed multipliers (any seed works: matches are verified byte for byte)


def frame_keys(rows: torch.Tensor) -> torch.Tensor:
    """(M, D) uint8 rows, D a multiple of 8 -> (M,) int64 keys: equal rows, equal keys."""
    if rows.dtype != torch.uint8 or rows.ndim != 2 or rows.shape[1] % 8:
        raise ValueError(f"frame_keys takes (M, D) uint8 rows with D a multiple of 8, got {rows.dtype} "
                         f"{tuple(rows.shape)}")
    words = rows.contiguous().view(torch.int64)  # (M, D / 8)
    g = torch.Generator().manual_seed(_KEY_SEED)
    mult = torch.randint(-2 ** 62, 2 ** 62, (words.shape[1],), generator=g, dtype=torch.int64) | 1
    return (words * mult.to(words.device)).sum(1)


class FrameCodes:
    """The (distinct frame -> code) pairs one encoder has computed in one block; ``encoder`` is watched so that a
    change of its weights (an optimiser step, a loaded state) empties the book instead of serving stale codes."""

    def __init__(self, encoder: nn.Module):
        self.encoder = encoder
        self.frames: torch.Tensor | None = None  # (K, D) uint8, the distinct frames seen, sorted by key
        self.keys: torch.Tensor | None = None    # (K,) int64, sorted
        self.codes: torch.Tensor | None = None   # (K, F) their codes
        self._weights = self._weights_state()
        self.encoded = 0                         # frames this book sent to the encoder (what tests count)

    def __deepcopy__(self, memo) -> None:
        """A copy of the model (the dissection's float64 passes copy it inside a block) gets no book: the book
        serves the block's own encoder, and copying it would copy every code the block has computed."""
        return None

    def _weights_state(self) -> list[tuple[int, int]]:
        return [(p.data_ptr(), p._version) for p in self.encoder.parameters()]

    def codes_of(self, distinct: torch.Tensor, encode: Callable[[torch.Tensor], torch.Tensor]) -> torch.Tensor:
        """distinct (M, D) uint8 rows, each row once -> their codes (M, F): the book's where it holds the frame,
        ``encode``'s ((m, D) uint8 -> (m, F)) for the others, which the book then keeps."""
        if self._weights_state() != self._weights or (self.frames is not None and (
                self.frames.device != distinct.device or self.frames.shape[1] != distinct.shape[1])):
            self.frames = self.keys = self.codes = None
            self._weights = self._weights_state()
        keys = frame_keys(distinct)
        if self.frames is None:
            new = torch.ones(distinct.shape[0], dtype=torch.bool, device=distinct.device)
            hit = torch.zeros(distinct.shape[0], dtype=torch.long, device=distinct.device)
        else:
            at = torch.searchsorted(self.keys, keys).clamp_max(self.keys.numel() - 1)
            new = ~((self.keys[at] == keys) & (self.frames[at] == distinct).all(1))  # verified byte for byte
            hit = at
        fresh = encode(distinct[new]) if bool(new.any()) else None
        self.encoded += int(new.sum())
        if self.codes is None:
            codes = fresh
        else:
            codes = self.codes.new_empty((distinct.shape[0], self.codes.shape[1]))
            codes[~new] = self.codes[hit[~new]]
            if fresh is not None:
                codes[new] = fresh.to(codes.dtype)
        if fresh is not None:
            frames = distinct[new] if self.frames is None else torch.cat([self.frames, distinct[new]])
            all_keys = keys[new] if self.keys is None else torch.cat([self.keys, keys[new]])
            all_codes = fresh if self.codes is None else torch.cat([self.codes, fresh.to(self.codes.dtype)])
            order = torch.argsort(all_keys, stable=True)
            self.frames, self.keys, self.codes = frames[order], all_keys[order], all_codes[order]
        return codes


@contextlib.contextmanager
def distinct_frames_once(model: nn.Module) -> Iterator[None]:
    """Inside the block, without autograd, each image encoder of ``model`` encodes every distinct uint8 frame once
    and gathers the codes back: the same features bit for bit as every frame encoded in chunks of at least
    ``parts.MIN_CODE_CHUNK`` frames (its chunks are padded to that size, and then a frame's code does not depend on the
    other frames of its chunk, tested), fewer conv passes where frames repeat. The pendulum's do: its clean frames are drawn
    from the rod bank's few hundred images, so 256 test sequences at max noise 0.5 hold about 15,000 distinct
    frames among 19,200. "Once" holds across the calls of the outermost block (``FrameCodes``): a blackout set
    made from a test set shares every frame outside its gap of pure noise, so a task that wraps both passes in
    one block encodes the blackout's gap frames only. Evaluation only: a camera never repeats a frame bit for
    bit, so training (autograd) and the timed inference (notebooks 05 and 06) encode every frame. The flags and
    books are restored in ``finally``."""
    encoders = [m for m in model.modules() if isinstance(m, ImageEncoder)]
    before = [(e.distinct_frames, e.frame_codes) for e in encoders]
    for e in encoders:
        e.distinct_frames = True
        e.frame_codes = e.frame_codes if e.frame_codes is not None else FrameCodes(e)  # the outermost block's book
    try:
        yield
    finally:
        for e, (flag, book) in zip(encoders, before):
            e.distinct_frames, e.frame_codes = flag, book


__all__ = ["FrameCodes", "distinct_frames_once", "frame_keys"]
