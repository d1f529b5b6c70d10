"""F1 and F2 are not claims the paper states but the premise of its method: a
recursive filter inside the network is only "a filter" if its observation noise r follows frame
quality (so the gain can fall on bad frames), its transition predicts, and its state coasts through
frames that hold nothing. The book checks them (notebook 02) before reading the claims; the
ablation's second round chose the book's DRF by the same thresholds
(``drfkit.study.ablation.mechanism_targets``). Both are judged per protocol on notebook 02's protocol
table (``f1_filter_mechanism``, ``f2_blackout_coasting``; their shared reading of it in
``dynamics_table``); F2 is labelled by what the protocol's training frames held, which notebook 02
records from ``pure_noise_training``."""
from __future__ import annotations

# F1's and F2's shared reading of notebook 02's table, here too under the names its readers import
from drfkit.study.claims.dynamics_table import UNKNOWN_TRAINING, training_label


def pure_noise_training(protocol: str) -> str | None:
    """Why the DRF of ``protocol`` sees pure-noise frames in training (``drfkit.methods.protocols``:
    blackouts, or a max noise of 1.0, where a frame can be all noise), or None when it never does:
    then a pure-noise blackout is out of its training distribution."""
    from drfkit.methods.protocols import PROTOCOLS, protocol_spec

    if "drf" not in PROTOCOLS.get(protocol, {}):
        return None
    spec = protocol_spec(protocol, "drf")
    if spec["blackouts"]:
        lo, hi = spec["blackouts"]["lengths"]
        return (f"this protocol trains with {lo}–{hi}-frame pure-noise blackouts in "
                f"{100 * spec['blackouts']['fraction']:.0f} % of its sequences")
    if spec["train_max_noise"] >= 1.0:
        return f"this protocol trains at max noise {spec['train_max_noise']:g}, where frames can be pure noise"
    return None


__all__ = ["pure_noise_training", "training_label", "UNKNOWN_TRAINING"]
