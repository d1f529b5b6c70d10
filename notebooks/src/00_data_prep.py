# %% [markdown]
# # 00 · Data preparation
#
# The study has two data sets, and this notebook builds (or loads from the cache) both,
# shows what they look like and checks that they are what they claim to be.
#
# 1. **The noisy pendulum** of the Recurrent Kalman Network benchmark (Becker et al. 2019):
#    24×24 images of a swinging rod, corrupted by a temporally correlated blend with uniform
#    noise. The paper trains with a *maximum* noise of 0.5 and tests at 0.5 and 0.75.
# 2. **Pedestrians**: PifPaf keypoints of pedestrians tracked over nuScenes keyframes, with
#    salt-and-pepper pixel noise (p = 0.01 to train, 0.025 and 0.05 out of distribution).
#    nuScenes and the PifPaf weights cannot be downloaded here, so by default the book uses a
#    *simulated* nuScenes-like source in the same record format (`drfkit.study.pedestrian_runs`);
#    set `ped_source = "nuscenes"` with `nuscenes_root` and `pifpaf_predictions` to use real data.
#
# Every data set is cached under `results/<profile>/data/` by a hash of the parameters that made it.

# %% tags=["parameters"]

# %%
from drfkit.book.runtime import start_notebook

P, timer = start_notebook("00_data_prep", globals())

# %%
import matplotlib.pyplot as plt
import numpy as np

from drfkit.study import studies
from drfkit.data.pendulum import estimate_angle
from drfkit.report.figures import new_figure
from drfkit.report.writers import save_figure

# %% [markdown]
# ## The noisy pendulum
#
# **Reading of "maximum noise".** The benchmark draws a per-sequence, temporally correlated
# factor f ∈ [0, 1] (first five frames clean) and blends `f · image + (1 − f) · uniform noise`.
# It has no "max noise" knob; we read the paper's "maximum amount of noise between 0 and 50 %"
# as rescaling the noise level n = 1 − f to n' = max_noise · n ∈ [0, max_noise]. The same seed
# at another max_noise gives the *same* pendulum motions and the same factor, so the 0.5 and
# 0.75 test sets differ only in how much noise is blended in.

# %%
splits = {split: studies.pendulum_split(P, split) for split in ("train", "val", "test")}
tests = {m: studies.pendulum_split(P, "test", m) for m in P.pendulum.eval_max_noise}
for split, arrays in splits.items():
    print(f"{split:5s}: images {arrays['images'].shape} {arrays['images'].dtype}, "
          f"targets {arrays['targets'].shape} (cos θ, sin θ)")

# %%
# Rendered angles agree with the targets: the rod's intensity centroid points along θ (to within the
# 2.5° that the benchmark's hard-edged, not anti-aliased rod allows).
clean = splits["test"]["clean"]
theta_hat = estimate_angle(clean)
theta = np.arctan2(splits["test"]["targets"][..., 1], splits["test"]["targets"][..., 0])
err_deg = np.degrees(np.abs(np.angle(np.exp(1j * (theta_hat - theta)))))
assert np.percentile(err_deg, 99) < 2.5, err_deg.max()
# The same motions at every test noise level; the noise never exceeds max_noise.
for m, arrays in tests.items():
    assert np.array_equal(arrays["clean"], tests[P.pendulum.eval_max_noise[0]]["clean"])
    assert arrays["noise"].max() <= m + 1e-6 and np.all(arrays["noise"][:, :5] == 0)
print("angle check passed: 99th percentile error below 2.5 degrees; test sets share their motions")

# %%
# NBVAL_IGNORE_OUTPUT
print(f"median angle error {np.median(err_deg):.2f} deg, 99th percentile {np.percentile(err_deg, 99):.2f} deg")

# %% [markdown]
# Sample frames: the noisiest test sequence, clean (top) and at each evaluation noise level.
# Frames 0–4 are always clean; later frames carry the correlated noise factor.

# %%
frames = np.linspace(0, P.pendulum.seq_len - 1, 8).astype(int)
k = int(tests[max(tests)]["noise"].mean(axis=1).argmax())
rows = [("clean", clean[k])] + [(f"max noise {m}", tests[m]["images"][k]) for m in P.pendulum.eval_max_noise]
fig, axes = new_figure(len(frames), len(rows), width=1.1, height=1.2)
for r, (name, seq) in enumerate(rows):
    for c, t in enumerate(frames):
        ax = axes[r, c]
        ax.imshow(seq[t], cmap="gray", vmin=0, vmax=255)
        ax.set_xticks([]); ax.set_yticks([])
        if r == 0:
            ax.set_title(f"t={t}", fontsize=8)
    axes[r, 0].set_ylabel(name, fontsize=7)
save_figure(P.profile, "pendulum_samples", fig)
plt.show()

# %%
fig, axes = new_figure(2)
for m, arrays in tests.items():
    axes[0, 0].hist(arrays["noise"][:, 5:].ravel(), bins=40, range=(0, 1), alpha=0.6, label=f"max {m}")
axes[0, 0].set_xlabel("per-frame noise level n'"); axes[0, 0].set_ylabel("frames"); axes[0, 0].legend()
axes[0, 1].plot(tests[max(tests)]["noise"][:4].T)
axes[0, 1].set_xlabel("frame"); axes[0, 1].set_ylabel("noise level"); axes[0, 1].set_title("four sequences")
save_figure(P.profile, "pendulum_noise_levels", fig)
plt.show()

# %% [markdown]
# ## Pedestrians
#
# One record per pedestrian per keyframe: 17 COCO keypoints (pixel u, v, confidence),
# camera intrinsics, the box centre in the camera frame (depth z is the target; the Euclidean
# distance is kept too), track, scene and image ids, and the noise level the keypoints came
# from. Records at different noise levels hold the same pedestrians.

# %%
from drfkit.data.drawing import draw_skeletons, render_frame

records = {p: studies.pedestrian_records(P, p) for p in sorted({0.0, P.pedestrians.train_p, *P.pedestrians.eval_p})}
base = records[P.pedestrians.train_p]
print(f"source: {P.pedestrians.source}")
print(f"images: {len(np.unique(base['image_id']))}, pedestrian instances (tracks): "
      f"{len(np.unique(base['track_id']))}, detections: {len(base['depth'])}, scenes: {len(np.unique(base['scene_id']))}")
split_seqs = {s: studies.pedestrian_split(P, s) for s in ("train", "val", "test")}
scene_sets = [set(np.unique(v["scene_id"])) for v in split_seqs.values()]
assert not (scene_sets[0] & scene_sets[1] or scene_sets[0] & scene_sets[2] or scene_sets[1] & scene_sets[2])
for s, v in split_seqs.items():
    print(f"{s:5s}: {v['inputs'].shape[0]} sequences of {P.pedestrians.seq_len} frames, {int(v['mask'].sum())} real frames")

# %%
# NBVAL_IGNORE_OUTPUT
detected = {p: len(r["depth"]) for p, r in records.items()}
print("detections per noise level:", detected)

# %% [markdown]
# A keyframe rendered at each noise level with the detected skeletons drawn on it. For the
# simulated source the picture is a schematic stand-in (the keypoints come from the simulated
# detector, not from PifPaf on this image).

# %%
image_id = int(np.bincount(base["image_id"]).argmax())  # the busiest keyframe
levels = sorted(records)[:4]
fig, axes = new_figure(2, (len(levels) + 1) // 2, width=5.5, height=3.3)
for ax, p in zip(axes.ravel(), levels):
    rec = records[p]
    img = render_frame(rec, image_id, p, seed=P.pedestrians.data_seed)
    img = draw_skeletons(img, rec["keypoints"][rec["image_id"] == image_id])
    ax.imshow(img); ax.set_title(f"salt-and-pepper p = {p}", fontsize=9); ax.axis("off")
for ax in axes.ravel()[len(levels):]:
    ax.axis("off")
save_figure(P.profile, "pedestrian_frames", fig)
plt.show()

# %%
fig, axes = new_figure(2)
axes[0, 0].hist(base["depth"], bins=40)
axes[0, 0].set_xlabel("depth z (m)"); axes[0, 0].set_ylabel("detections")
conf = {p: r["keypoints"][..., 2].mean() for p, r in records.items()}
axes[0, 1].plot(list(conf), list(conf.values()), "o-")
axes[0, 1].set_xlabel("salt-and-pepper p"); axes[0, 1].set_ylabel("mean keypoint confidence")
save_figure(P.profile, "pedestrian_depths", fig)
plt.show()
assert 0 < base["depth"].min() and base["depth"].max() < 80

# %%
_ = timer.finish()
