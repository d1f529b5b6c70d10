# %% [markdown]
# # 01 · Pendulum: training DRF and the baselines
#
# Three models read the same 24×24 noisy frames through the same image encoder and observation
# heads (w = LayerNorm(Linear₁(x)), R = diag(ELU(Linear₂(x)) + 1), latent size 30) and the same
# decoder (mean and σ, dropout for MC sampling). They differ only in what connects the two:
#
# * **no_dynamics** — nothing: the decoder reads [w_t, diag R_t] of the current frame;
# * **LSTM** — a vanilla LSTM over [w_t, diag R_t];
# * **DRF** — the deep recursive filter: a state transition network (two LSTM layers) predicts
#   F_t and Q_t, a Kalman predict/update step fuses the latent observation w_t with the prior,
#   and the decoder reads the posterior [z_t, diag P_t].
#
# All three are trained with the book's one training loop (`drfkit.train`): Gaussian NLL
# averaged over every frame of a sequence (the paper's loss), Adam, gradient clipping at norm
# 10, the best checkpoint on validation NLL, a checkpoint every epoch from which an interrupted
# run resumes. The paper's schedule is Adam 1e-4 for 200 epochs; it does not state the batch
# size: we use 50 sequences. Trained on max noise 0.5, tested at 0.5 and 0.75 (out of distribution).

# %% tags=["parameters"]

# %%
from drfkit.runtime import start_notebook

P, timer = start_notebook("01_pendulum_training", globals())

# %%
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from drfkit import studies
from drfkit.evaluate import evaluate_study, summarise
from drfkit.paper import PENDULUM_MAE, PENDULUM_PICP_MPIW
from drfkit.report import (color, label, new_figure, paper_comparison, plot_mae_bars, plot_picp_mpiw, save_figure,
                           save_table)

# %% [markdown]
# ## Training
# Every model for every seed; a finished run is loaded from its checkpoint, an interrupted one resumes.

# %%
# NBVAL_IGNORE_OUTPUT
results = studies.train_models(P, "pendulum")
curves = pd.read_csv(studies.tables_dir(P.profile) / "pendulum_training_curves.csv")
curves.groupby("model")[["train_loss", "val_loss", "seconds"]].last()

# %%
assert set(curves["model"]) == set(P.pend_models) and set(curves["seed"]) == set(P.seeds)
assert len(curves) == len(P.pend_models) * len(P.seeds) * P.pend_epochs
assert np.isfinite(curves[["train_loss", "val_loss"]].to_numpy()).all()
print(f"{len(results)} runs trained for {P.pend_epochs} epochs each; checkpoints in results/{P.profile}/models/")

# %%
fig, axes = new_figure(2)
for (kind, seed), run in curves.groupby(["model", "seed"]):
    axes[0, 0].plot(run["epoch"], run["train_loss"], color=color(kind), alpha=0.7,
                    label=label(kind) if seed == P.seeds[0] else None)
    axes[0, 1].plot(run["epoch"], run["val_loss"], color=color(kind), alpha=0.7)
axes[0, 0].set_title("training NLL"); axes[0, 1].set_title("validation NLL")
for ax in axes[0]:
    ax.set_xlabel("epoch")
axes[0, 0].legend()
save_figure(P.profile, "pendulum_training_curves", fig)
plt.show()

# %% [markdown]
# ## Speed of training
# One optimisation step (forward, loss, backward) of each model on the same batch of 50 × T frames,
# measured with `torch.utils.benchmark` in one run; seconds per epoch follow from the number of
# batches. The target is a DRF epoch at most 1.5× a no_dynamics epoch.

# %%
# NBVAL_IGNORE_OUTPUT
from drfkit.timing import training_step_times

train = studies.pendulum_data(P, "train")
batch = min(50, len(train))
speed = training_step_times({k: studies.model_config("pendulum", k) for k in ["no_dynamics", "lstm", "drf"]},
                            train.inputs[:batch], train.targets[:batch],
                            n_batches_per_epoch=int(np.ceil(P.pend_train_sequences / batch)),
                            min_run_time=0.5)
save_table(P.profile, "pendulum_training_speed", speed)
speed

# %% [markdown]
# ## Accuracy: MAE at the training noise and out of distribution
# MAE over both state components (cos θ, sin θ) and all frames of the test sequences, mean over
# seeds with a 95 % t-interval; the paper's values are the black ticks.

# %%
evals = evaluate_study(P, "pendulum", P.pend_eval_max_noise)
summary = summarise(evals, ["model", "noise"])
save_table(P.profile, "pendulum_eval", evals)
save_table(P.profile, "pendulum_mae", summary)
assert len(evals) == len(P.pend_models) * len(P.seeds) * len(P.pend_eval_max_noise)
assert evals[["mae", "picp", "mpiw", "nll"]].notna().all().all() and (evals["mae"] > 0).all()

# %%
# NBVAL_IGNORE_OUTPUT
summary[["model", "noise", "n_seeds", "mae", "mae_ci", "picp", "mpiw", "nll"]].round(4)

# %%
fig = plot_mae_bars(summary, P.pend_models, PENDULUM_MAE, ylabel="MAE (cos θ, sin θ)", level_name="max noise")
save_figure(P.profile, "pendulum_mae", fig)
plt.show()

# %% [markdown]
# ## Uncertainty: PICP against MPIW as the dropout rate varies
# 95 % central Gaussian intervals from the total σ (aleatoric and epistemic combined), with
# `n_samples` MC dropout passes through the decoder, at several dropout rates (the paper's curve).

# %%
curve = evaluate_study(P, "pendulum", P.pend_eval_max_noise, P.dropout_rates)
curve_summary = summarise(curve, ["model", "noise", "dropout_p"])
save_table(P.profile, "pendulum_picp_mpiw", curve_summary)
assert set(curve["dropout_p"]) == set(P.dropout_rates)

# %%
fig = plot_picp_mpiw(curve_summary, P.pend_models, PENDULUM_PICP_MPIW, level_name="max noise",
                     nominal=P.interval_level)
save_figure(P.profile, "pendulum_picp_mpiw", fig)
plt.show()

# %% [markdown]
# ## How this compares with the paper
# Our seed-mean MAE beside the paper's for every model and noise level, and the ratio. In the
# quick profile (a few epochs on 100 short sequences) the models are far from converged, so the
# ratios say only that the pipeline runs; `results/paper/` holds the paper-scale run, and the
# claims table of notebook 03 applies the paper's comparisons (C1, C2) with computed verdicts.

# %%
# NBVAL_IGNORE_OUTPUT
comparison = paper_comparison(summary, PENDULUM_MAE)
save_table(P.profile, "pendulum_mae_vs_paper", comparison)
for r in comparison.itertuples():
    print(f"{label(r.model):12s} max noise {r.noise}: ours {r.ours:.4f} ± {r.ours_ci:.4f}, paper {r.paper:.4f} "
          f"({r.ours_over_paper:.1f}x the paper's)")

# %%
_ = timer.finish()
