"""Another DRF judged in the paper's DRF's place: the DRF claims (C1, C2, F1, F2) again, one row each, for a
DRF kind a study's registry entry names (``Study.judged_drfs``: the pendulum's fifth-round choice), under each
protocol that trained it. Each model keeps its own row: the paper's DRF's verdict never borrows another model's
numbers, and the other DRF's rows say whose they are (the protocol cell ``"<protocol>: <kind>"`` and "ours"
begins with the kind).

The rules themselves do not change: the rows they read are the protocol's, with the named kind's rows as
``drf`` and the paper's DRF's rows left out (``as_drf``)."""
from __future__ import annotations

from typing import Iterator

import pandas as pd

SEPARATOR = ": "


def label(protocol: str, kind: str) -> str:
    """The protocol cell of ``kind``'s rows judged under ``protocol`` ('book: drf_calibrated_steep')."""
    return f"{protocol}{SEPARATOR}{kind}"


def split_label(cell: str) -> tuple[str, str]:
    """(protocol, kind) of a protocol cell; kind '' for the paper's DRF's own rows."""
    protocol, _, kind = str(cell).partition(SEPARATOR)
    return protocol, kind


def protocol_words(cell: str) -> str:
    """A protocol cell in words: 'book protocol', or 'drf_calibrated_steep, book protocol'."""
    protocol, kind = split_label(cell)
    return f"{kind}, {protocol} protocol" if kind else f"{protocol} protocol"


def as_drf(frame: pd.DataFrame, kind: str) -> pd.DataFrame:
    """``frame``'s rows with ``kind``'s rows renamed 'drf' and the paper's DRF's rows left out (frame: a table
    with a 'model' column)."""
    out = frame[frame["model"].ne("drf")].copy()
    out.loc[out["model"].eq(kind), "model"] = "drf"
    return out


def variants(protocol: str, kinds, *frames: pd.DataFrame) -> Iterator[tuple[str, str, tuple[pd.DataFrame, ...]]]:
    """(protocol cell, kind, frames) for the paper's DRF (kind '', the frames as given), then for each of
    ``kinds`` that the first frame holds (``as_drf`` of every frame)."""
    yield protocol, "", frames
    for kind in kinds:
        if frames and frames[0]["model"].eq(kind).any():
            yield label(protocol, kind), kind, tuple(as_drf(f, kind) for f in frames)


def tag(row: dict, kind: str) -> dict:
    """A claims row judged for ``kind`` in the DRF's place says so at the start of 'ours'."""
    return row if not kind else {**row, "ours": f"{kind} as the DRF: {row['ours']}"}


__all__ = ["SEPARATOR", "label", "split_label", "protocol_words", "as_drf", "variants", "tag"]
