"""Notebook 02's protocol table as F1 and F2 read it: each protocol's DRF rows, what the protocol's
training frames held (a blackout is out of distribution only for a DRF never trained on pure noise),
and where the two claims' evidence lies. Nothing here reads the training recipes themselves
(``mechanism.pure_noise_training`` does), so the claims' modules stay clear of the methods layer."""
from __future__ import annotations

from typing import Iterator

import pandas as pd

# the label of a table made before it recorded its training frames (``pure_noise_training`` column)
UNKNOWN_TRAINING = ("in or out of distribution unknown (the table predates the record of its training frames; "
                    "rerun notebook 02)")


def training_label(table: pd.DataFrame) -> str | None:
    """What a protocol table says of its models' training frames: its ``pure_noise_training`` column
    (written by notebook 02 from the recipe the checkpoints were trained with; '' = none), or
    ``UNKNOWN_TRAINING`` for a table without the column."""
    if "pure_noise_training" not in table:
        return UNKNOWN_TRAINING
    values = {str(v) for v in table["pure_noise_training"].fillna("")}
    if len(values) != 1:
        raise ValueError(f"a protocol's table holds several training-frame records: {sorted(values)}")
    return values.pop() or None


def drf_protocols(tables) -> Iterator[tuple[str, pd.DataFrame]]:
    """(protocol, its rows) of notebook 02's ``pendulum_protocols.csv`` (both protocols' DRF mechanism
    checks and blackout MAE, per seed) for each protocol that has DRF rows; nothing without the table
    (``tables``: ``judge.Tables``)."""
    protocols = tables.read("pendulum_protocols")
    if protocols is None:
        return
    for protocol, part in protocols.groupby("protocol", sort=False):
        if (part["model"] == "drf").any():
            yield protocol, part


# where F1 and F2 are judged: both protocols' rows are in these tables (pendulum_mechanism.csv and
# pendulum_blackout.csv hold the paper's only); ``table.Claim``'s fields
MECHANISM_EVIDENCE = dict(notebook="02_pendulum_dynamics", source="notebook 02, pendulum",
                          section="Both protocols side by side")


__all__ = ["UNKNOWN_TRAINING", "training_label", "drf_protocols", "MECHANISM_EVIDENCE"]
