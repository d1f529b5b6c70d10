# %% [markdown]
# # 03 · Pedestrians: training DRF, the baselines and Monoloco
#
# The second experiment estimates the depth z of pedestrians from their 17 COCO keypoints
# (PifPaf on nuScenes images in the paper). Keypoints are back-projected with each image's own
# intrinsics to normalised camera coordinates (10 · K⁻¹ [u, v, 1], as Monoloco does) and, with
# their confidences, form the 17 × 3 input of every model. The target is **depth z** in the camera
# frame (the paper's choice; Monoloco itself predicts the Euclidean distance).
#
# * **DRF, no_dynamics, LSTM** share a keypoint encoder and the pendulum study's heads and decoder;
#   they read tracks cut into sequences of `ped_seq_len` keyframes (2 Hz) at salt-and-pepper p = 0.01
#   (paper: Adam 1e-4, 200 epochs; batch size is ours), under each training protocol of `ped_protocols`
#   (`drfkit.methods.protocols.PEDESTRIAN_PROTOCOLS`): the paper's Gaussian NLL, and the book's
#   objective and schedule from the pendulum study (β-NLL with β = 1, which fits the mean where the NLL
#   starves it; cosine decay of the learning rate; the checkpoint kept on the validation MAE).
# * **Monoloco** (ICCV 2019) is the single-frame baseline, as its published code has it: 0.41 M
#   parameters, relative Laplace loss, its own schedule (Adam 2e-3, batch 256, StepLR 20/0.9,
#   150 epochs, no gradient clipping) under every protocol (one set of runs), trained on frames, the
#   epoch selected on validation L1 of mu; its input centres all 17 keypoints on the box around them, the placeholders of missed
#   keypoints included (PifPaf's pixel (0, −3), back-projected); at test time only its first
#   dropout is switched on. The DRF family's encoder instead centres on the detected keypoints
#   and zeroes missed ones (its confidences say which), a choice of ours.
# * **Depth, not distance.** Every model here, Monoloco included, is trained on depth z, the DRF
#   paper's target, so one table compares them. Monoloco's own target is the distance ‖centre‖;
#   for a pedestrian at lateral offset x, distance = √(z² + x² + y²) exceeds depth by a few
#   centimetres in front of the car and by up to ~15 % at the image edge (CAM_FRONT's ±35°), so
#   Monoloco's published errors and ours are not on the same scale, and its relative loss
#   weighs the two slightly differently. The comparison between models is unaffected.
#
# Unless `ped_source = "nuscenes"`, the records come from the simulated nuScenes-like source
# (`drfkit.data.sim_detector`): its keypoint detector **stands in for PifPaf on noisy images**,
# so absolute errors are not comparable with the paper's; the comparison between models is.

# %% tags=["parameters"]

# %%
from drfkit.book.runtime import start_notebook

P, timer = start_notebook("03_nuscenes_training", globals())

# %%
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from drfkit.study import claims, registry, studies
from drfkit.study.evaluate import evaluate_study, summarise
from drfkit.report.figures import label, plot_mae_bars, plot_training_curves
from drfkit.study.paper import PEDESTRIAN_MAE
from drfkit.report.writers import paper_comparison, save_figure, save_table
from drfkit.methods.train import load_checkpoint

# %% [markdown]
# ## How realistic is the simulated source?
# With `ped_source = "simulated"` every pedestrian verdict (C3, C4, C5, C7b) rests on a hand-set
# simulator: `drfkit.data.sim_detector` perturbs the true projected keypoints instead of running
# PifPaf on noisy images, with parameters (`pedestrians.sim_detector` in the profile) set by hand
# when the book was founded and not fitted to PifPaf on nuScenes: no record says how they were
# chosen (`docs/simulator.md` goes through each). Below, the simulator's statistics at the profile's
# evaluation levels, by true depth (`drfkit.data.sim_stats`): missed detections, missed keypoints,
# keypoint pixel error, and the error of a naive pinhole depth from the keypoints' vertical extent.

# %%
# NBVAL_IGNORE_OUTPUT
from drfkit.data import sim_stats
from drfkit.study.sim_stats import simulate_profile

if P.pedestrians.source == "simulated":
    sim_truth, sim_records = simulate_profile(P)
    for level, sim_rec in sim_records.items():
        ac = sim_stats.error_autocorrelation(sim_truth, sim_rec)
        print(f"p = {level:g}: {sim_stats.dataset_size(sim_truth, sim_rec)}; keypoint-error correlation between "
              f"consecutive keyframes {ac['keypoint']:+.3f}")
    sim_table = sim_stats.simulator_table(sim_truth, sim_records)
    print(sim_table[["p", "bin", "n_true", "miss_rate", "height_px", "kp_miss_rate", "err_px_median",
                     "err_rel_median", "gross_rate", "pinhole_mae_m"]].round(3).to_string(index=False))
else:
    print("the records come from nuScenes + PifPaf: the simulator's statistics do not apply")

# %% [markdown]
# **Reading.** By construction every error grows with p and (relative to the person's size) with
# distance, and is drawn **independently in every frame**: the correlation of keypoint errors between
# consecutive keyframes is about 0. Real PifPaf errors need not be independent -- occlusion,
# truncation and a person's pose last over several keyframes -- so a filter here may gain more from
# averaging over frames than it would on real data. Neither the paper nor the facts this book draws
# on (REFERENCE.md) give PifPaf's miss rates or keypoint errors by distance on nuScenes, so those
# statistics cannot be checked. What can be compared points one way: on the paper profile the naive
# pinhole estimate already reaches about 2.3 m at p = 0.01, near the paper's *learned* models on real
# data (2.56 m), while the learned models here reach 0.83-0.87 m (Monoloco 1.42 m): the simulated
# source is much easier than the real one. And the simulated shift is harsher: the DRF's MAE grows
# 2.4-fold from p = 0.01 to 0.05 here, 1.06-fold in the paper. Absolute pedestrian numbers and the
# size of the out-of-distribution effect are properties of the simulator. `docs/simulator.md` has
# the paper-profile table, each parameter, and why the pedestrian blackout below costs the learned
# models 13-30 m against the constant-velocity reference's 1.7 m.

# %%
# NBVAL_IGNORE_OUTPUT
PROTOCOLS = registry.study("pedestrians").protocols(P)  # the paper's first
results = {pr: studies.train_models(P, "pedestrians", protocol=pr) for pr in PROTOCOLS}
curves = {pr: pd.read_csv(studies.tables_dir(P.profile) / f"{studies.curves_name('pedestrians', pr)}.csv")
          for pr in PROTOCOLS}
pd.concat([c.assign(protocol=pr) for pr, c in curves.items()]).groupby(["protocol", "model"])[
    ["train_loss", "val_loss", "seconds"]].last()

# %%
for pr, c in curves.items():
    assert set(c["model"]) == set(P.pedestrians.models) and set(c["seed"]) == set(P.seeds), pr
    assert np.isfinite(c[["train_loss", "val_loss"]].to_numpy()).all(), pr
print(f"{sum(map(len, results.values()))} runs of {len(PROTOCOLS)} protocol(s); checkpoints in results/{P.profile}/models/")

# %%
# the paper's protocol: validation NLL of the DRF family, Monoloco's validation L1 (m); the book's: every
# run selected on validation L1 (m); kept epochs starred
for pr, c in curves.items():
    fig = plot_training_curves(c, P.pedestrians.models)
    fig.suptitle(f"{pr} protocol", fontsize=9)
    save_figure(P.profile, "pedestrians_training_curves" if pr == "paper" else f"pedestrians_{pr}_training_curves", fig)
    plt.show()

# %% [markdown]
# ## In-distribution accuracy (p = 0.01)
# Depth MAE in metres on the test scenes, mean over seeds with a 95 % t-interval, per training
# protocol. Out-of-distribution levels are the subject of notebook 04.

# %%
models = {pr: studies.trained_models(P, "pedestrians", protocol=pr) for pr in PROTOCOLS}
evals = pd.concat([evaluate_study(P, "pedestrians", [P.pedestrians.train_p], models=models[pr]).assign(protocol=pr)
                   for pr in PROTOCOLS], ignore_index=True)
summary = summarise(evals, ["protocol", "model", "noise"])
save_table(P.profile, "pedestrians_in_distribution", summary)
assert len(evals) == len(PROTOCOLS) * len(P.pedestrians.models) * len(P.seeds) and (evals["mae"] > 0).all()

# %%
# NBVAL_IGNORE_OUTPUT
summary[["protocol", "model", "n_seeds", "mae", "mae_ci", "picp", "mpiw", "nll"]].round(3)

# %%
for pr in PROTOCOLS:
    fig = plot_mae_bars(summary[summary["protocol"] == pr], P.pedestrians.models, PEDESTRIAN_MAE, ylabel="depth MAE (m)",
                        level_name="p", width=5)
    fig.axes[0].set_title(f"{pr} protocol", fontsize=9)
    save_figure(P.profile, "pedestrians_in_distribution_mae" if pr == "paper" else f"pedestrians_{pr}_in_distribution_mae",
                fig)
    plt.show()

# %% [markdown]
# Beside the paper's in-distribution MAE (real nuScenes and PifPaf). With the simulated source the
# absolute values measure our stand-in detector, not PifPaf on nuScenes; what carries over is the
# ranking of the models, which notebook 04 tests (C3, C4) under each protocol.

# %%
# NBVAL_IGNORE_OUTPUT
for pr in PROTOCOLS:
    for r in paper_comparison(summary[summary["protocol"] == pr], PEDESTRIAN_MAE).itertuples():
        print(f"{pr:6s} {label(r.model):12s} p = {r.noise}: ours {r.ours:.2f} ± {r.ours_ci:.2f} m, paper {r.paper:.2f} m")

# %% [markdown]
# ## Is Monoloco handicapped, or is the source hard for it?
# In the paper Monoloco is 25 % *better* than the per-frame no_dynamics in distribution; here it is
# worse. Two readings: its published input (all 17 keypoints centred on the box around them, the
# placeholders of missed keypoints included, no confidences) hides what the DRF family's encoder
# sees, or its network and loss suit this source less. To tell them apart the same network, loss and
# schedule are trained on the DRF family's 53 inputs (`Monoloco(inputs="detected")`: the detected
# keypoints centred on their own box, missed ones 0, that centre, and the confidences). Not a model of
# the paper, but the fair comparator: claims C3 and C4 (notebook 04) are judged against this
# input-matched Monoloco, with Monoloco as published kept beside it as a second, unjudged comparison;
# its per-seed rows (`pedestrians_monoloco_inputs_by_seed.csv`) let notebook 04 pair it with the DRF
# by seed.

# %%
# NBVAL_IGNORE_OUTPUT
diagnostic = studies.train_models(P, "pedestrians", kinds=["monoloco"], options={"inputs": "detected"})
fed = {("monoloco_detected_inputs", seed): load_checkpoint(res.best_path) for (_, seed), res in diagnostic.items()}
inputs_levels = sorted({P.pedestrians.train_p, *P.pedestrians.eval_p})  # each level once: a seed counts once
inputs_evals = pd.concat([evaluate_study(P, "pedestrians", inputs_levels, models=fed),
                          evaluate_study(P, "pedestrians", inputs_levels,
                                         models={k: m for k, m in models["paper"].items()
                                                 if k[0] in ("monoloco", "no_dynamics")})], ignore_index=True)
assert not inputs_evals.duplicated(["model", "seed", "noise"]).any()
inputs_summary = summarise(inputs_evals, ["model", "noise"])
save_table(P.profile, "pedestrians_monoloco_inputs", inputs_summary)
save_table(P.profile, "pedestrians_monoloco_inputs_by_seed", inputs_evals)  # notebook 04 pairs it with the DRF by seed
inputs_summary.pivot(index="model", columns="noise", values="mae").round(3)

# %%
# NBVAL_IGNORE_OUTPUT
reading = claims.monoloco_inputs_reading(inputs_summary, P.pedestrians.train_p)
assert reading["text"]
print(reading["text"])

# %% [markdown]
# `claims.monoloco_inputs_reading` states the rule: the share of Monoloco's gap to no_dynamics (in
# distribution, seed means) that its network closes when fed the DRF family's inputs; at least half
# means the gap is mostly its published inputs, less than half mostly its network, loss or schedule.

# %% [markdown]
# ## The headline: is the family's encoder the bottleneck, or the recurrence?
# The single-frame, input-matched Monoloco is more accurate than every model of the DRF family, the
# per-frame no_dynamics included, at every level. no_dynamics is the family's encoder alone, frame by frame,
# so the recurrence cannot be what holds the family back: its encoder is (53 -> 128 -> 64, 23 k weights in
# no_dynamics against Monoloco's 412 k). One serious attempt at a recipe, as the wider encoder was the
# pendulum's lever: no_dynamics and the DRF with the encoder at about Monoloco's width
# (`drfkit.study.pedestrian_runs.WIDE_KEYPOINT_MODELS`: hidden 512, features 256, decoder 256), the paper
# protocol's schedule, every seed, judged in distribution. `claims.encoder_width_reading` states the rule: the
# share of no_dynamics' gap to the input-matched Monoloco that the width closes; at least half calls the width
# the bottleneck.

# %%
# NBVAL_IGNORE_OUTPUT
from drfkit.study.pedestrian_runs import WIDE_KEYPOINT_MODELS

wide = {(kind + claims.WIDE_SUFFIX, seed): load_checkpoint(res.best_path)
        for kind in ("no_dynamics", "drf")
        for (_, seed), res in studies.train_models(P, "pedestrians", kinds=[kind], options=WIDE_KEYPOINT_MODELS,
                                                   write_curves=False).items()}
width_evals = pd.concat([evaluate_study(P, "pedestrians", inputs_levels, models=wide),
                         inputs_evals[inputs_evals["model"].isin([claims.MATCHED_MONOLOCO, "no_dynamics"])],
                         evaluate_study(P, "pedestrians", inputs_levels,
                                        models={k: m for k, m in models["paper"].items() if k[0] == "drf"})],
                        ignore_index=True)
width_summary = summarise(width_evals, ["model", "noise"])
save_table(P.profile, "pedestrians_encoder_width", width_summary)
print(claims.encoder_width_reading(width_summary, P.pedestrians.train_p)["text"])
width_summary.pivot(index="model", columns="noise", values="mae").round(3)

# %% [markdown]
# ## A reference: a filter with the motion model, and a blackout
# **This reference uses knowledge the learned models do not have**: that a person's depth changes
# at a nearly constant rate between keyframes (constant velocity, white-acceleration noise for the
# walkers' turns and the ego car's drift; `drfkit.methods.references.constant_velocity_filter`). Fed each
# no_dynamics seed's per-frame depths and σ (scale and acceleration noise chosen on the validation scenes at
# p = 0.01), it shows what this filter makes of the same per-frame estimates: a reference, not a
# bound on what any model could reach (a model may do better, e.g. with an encoder trained through a
# filter). The *blackout* removes the detections of frames 4–6 of every full window (keypoints zeroed,
# confidence 0): the reference is told
# they are missing and predicts through them; the learned models are fed the zeroed frames, which no
# training window ever held (a missed detection is left out of its track), and every model reads one as
# a person about 50 m away, so their error there measures that, not coasting (docs/simulator.md,
# section 4). MAE on the removed frames.

# %%
# NBVAL_IGNORE_OUTPUT
from drfkit.study import dynamics

# per protocol: the reference moves with the no_dynamics whose estimates it filters
reference = pd.concat([dynamics.pedestrian_reference(P, {s: m for (k, s), m in models[pr].items() if k == "no_dynamics"},
                                                     models[pr]).assign(protocol=pr) for pr in PROTOCOLS],
                      ignore_index=True)
save_table(P.profile, "pedestrians_reference", reference)
assert (reference["mae"] > 0).all() and set(reference["noise"]) >= {"blackout"}
reference.groupby(["protocol", "model", "noise"])["mae"].mean().unstack().round(3)

# %%
_ = timer.finish()
