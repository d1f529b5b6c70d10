# %% [markdown]
# # 05 · Timing: what uncertainty costs per frame
#
# The paper reports that DRF computes its aleatoric and epistemic uncertainty about 3× faster than
# Monoloco: 12.3 ms against 36.1 ms for "25 forward passes", after the PifPaf keypoint extraction
# that both share, on a GTX 1080 (claim C6). The reason is structural: Monoloco's dropout sits in
# every layer, so each Monte Carlo sample is a pass through the whole network, whereas DRF's
# dropout sits only in its small decoder, so the encoder and the filter run once and only the
# decoder is sampled. This notebook measures that cost on the machine at hand.
#
# **What one measurement is.** The latency of predicting, for B pedestrians at once, the depth of
# each in one new frame with its uncertainty, from normalised keypoints (B, 1, 17, 3) — after
# keypoint extraction, as in the paper. Sequence models run *one streaming step*: DRF encodes the
# frame and runs one transition + Kalman predict/update step from the posterior carried over from
# the previous frame; the LSTM runs one step from its carried (h, c); no_dynamics and Monoloco have
# no state. (A length-1 sequence would skip the filter altogether; dividing a T-step sequence by T
# would spread the encoder's and decoder's per-call cost over frames an online system has not seen
# yet.) `tests/test_timing.py` checks that the streaming step reproduces `model.features` on whole
# sequences. The prediction includes the mixture moments (mean, aleatoric, epistemic, total σ).
#
# **Modes** (S = `n_samples` dropout samples):
#
# | model | mode | what runs |
# |---|---|---|
# | Monoloco | `published` | S dropout passes through the whole MLP, one after the other (as Monoloco's code) |
# | Monoloco | `batched` | the same S passes folded into one batched call |
# | DRF | `batched` | encoder + filter step once, S decoder samples in one call (the book's `predict`) |
# | DRF | `sequential` | encoder + filter step once, S separate decoder calls |
# | DRF | `naive` | S complete forward passes, the filter step included in each |
# | no_dynamics, LSTM | `batched` | as DRF `batched` |
# | every model | `no_sampling` | one deterministic pass (dropout off): mean and aleatoric σ only |
#
# The same is measured for the pendulum models on one 24×24 uint8 frame per sequence. The last part
# of the notebook times *training*: a DRF epoch against a no_dynamics epoch on the pendulum.
#
# **Protocol.** `torch.utils.benchmark`: per configuration, warm-up calls, then three
# interleaved rounds over all configurations of a (batch, threads, device) group, each round
# timing each configuration with `blocked_autorange(min_run_time / 3)` (blocks of repeated
# calls, CUDA synchronised around each block); interleaving makes a change in machine load
# during a group hit all its configurations alike rather than bias their ratios. We report the
# median and the interquartile range of the per-call times of all blocks, divided by B (ms per
# pedestrian-frame). Batch sizes `timing_batch_sizes`, intra-op thread counts `timing_threads`
# (`benchmark.Timer(num_threads=...)`), on CPU and also on CUDA when torch sees a GPU. Models are
# built fresh from their default configurations under a fixed seed, in eval mode, under
# `torch.inference_mode`: weights do not change the cost (no data-dependent control flow), so no
# training is needed. **Ratios are taken only between measurements of one run and one
# (batch, threads, device) group** — machines and runs differ too much for anything else.
# The pendulum has no Monoloco: there its ratios are to each model's own `no_sampling` pass.
#
# **Reruns.** A measurement made on this machine with the same code and parameters is reused
# (`drfkit.book.measurements`: the cell says so and when it was measured); `make reproduce REMEASURE=1`
# or `make bench` measures again.

# %% tags=["parameters"]

# %%
from drfkit.book.runtime import start_notebook

P, timer = start_notebook("05_timing", globals())

# %%
import os

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from drfkit.study import claims
from drfkit.study.claims import judge
from drfkit.report.figures import color, label, new_figure
from drfkit.study.paper import TIMING_MS, TIMING_SPEEDUP
from drfkit.report.writers import save_figure, save_table
from drfkit.book.measurements import cached
from drfkit.book.bench_store import COMMAND as BENCH_COMMAND, bench_dir, describe, read_bench, write_bench
from drfkit.study.bench import COLUMNS, MODES, STUDIES, add_ratios, lookup, speedup_vs_monoloco, timing_devices

# %% [markdown]
# ## The benchmark
# Every (model, mode) at every batch size, thread count and device, in one run: a measurement of its own,
# made by `make bench PROFILE=<profile>` (`drfkit.book.bench_store`) into `results/<profile>/bench/` with its
# own manifest (the command, the machine, when, the load around it). This notebook reads it, so a cold
# reproduce does not time the grid again; where the profile has none for its current parameters, the
# notebook runs that command's function itself. The table is copied to `tables/timing.csv`.

# %%
# NBVAL_IGNORE_OUTPUT
stored = read_bench(P)
if stored is None:
    print(f"no benchmark of these parameters in {bench_dir(P.profile)}: timing the grid now "
          f"(what `{BENCH_COMMAND.format(profile=P.profile)}` does)")
    stored = write_bench(P)
table, bench_record = stored
load_before, load_after = bench_record["load_before"], bench_record["load_after"]
print(f"the grid: {describe(bench_record)}")
save_table(P.profile, "timing", table)
table[table["batch"] == min(P.timing.batch_sizes)].drop(columns=["n_samples", "load_1min"]).round(4)

# %%
devices = timing_devices(P.device)
pairs = [(study, kind, mode) for study, (_, _, kinds) in STUDIES.items() for kind in kinds for mode in MODES[kind]]
expected = {(*pair, b, t, d) for pair in pairs for b in P.timing.batch_sizes for t in P.timing.threads
            for d in devices}
cells = list(zip(table["study"], table["model"], table["mode"], table["batch"], table["threads"], table["device"]))
assert list(table.columns) == COLUMNS
assert len(cells) == len(set(cells)) and set(cells) == expected, "a configuration is missing or measured twice"
assert (table["median_ms_per_frame"] > 0).all() and np.isfinite(table["median_ms_per_frame"]).all()
assert (table["iqr_ms_per_frame"] >= 0).all()
recomputed = add_ratios(table)
for col in ("ratio_to_monoloco_published", "ratio_to_no_sampling"):
    assert np.allclose(recomputed[col], table[col], equal_nan=True), f"{col} is not medians / same-group base"
assert table.loc[table["study"] == "pendulum", "ratio_to_monoloco_published"].isna().all()
print(f"measured {len(pairs)} model/mode pairs x {len(P.timing.batch_sizes)} batch sizes x "
      f"{len(P.timing.threads)} thread counts on each device; every ratio is within one "
      f"(batch, threads, device) group")

# %% [markdown]
# ## Milliseconds per frame
# CPU, at the thread count used for the claim (below); log scales. Solid lines: the S-sample
# predictions the paper compares; dotted: the deterministic pass of the same model.

# %%
claim_threads = min(P.timing.threads)
styles = {"published": ("-", "s"), "batched": ("-", "o"), "sequential": ("--", "^"), "naive": ("-.", "v"),
          "no_sampling": (":", ".")}
fig, axes = new_figure(2, width=5.2, height=3.8)
for ax, study in zip(axes[0], STUDIES):
    rows = table[(table["study"] == study) & (table["device"] == "cpu") & (table["threads"] == claim_threads)]
    for (kind, mode), run in rows.groupby(["model", "mode"], sort=False):
        ls, marker = styles[mode]
        run = run.sort_values("batch")
        ax.plot(run["batch"], run["median_ms_per_frame"], ls=ls, marker=marker, ms=4, color=color(kind),
                label=f"{label(kind)} {mode}")
    ax.set_xscale("log"); ax.set_yscale("log")
    ax.set_xlabel("batch (frames per call)"); ax.set_ylabel("ms per frame (median)")
    ax.set_title(f"{study}, CPU, {claim_threads} thread(s), S = {P.uncertainty.n_samples}")
    ax.legend(fontsize=6)
save_figure(P.profile, "timing_ms_per_frame", fig)
plt.show()

# %% [markdown]
# ## The paper's numbers beside ours
# The paper's table gives one time per method for "25 forward passes" on a GTX 1080 without
# stating the batch; ours are per pedestrian-frame at batch 1 (one pedestrian), on CPU at
# `claim_threads` thread(s), and on CUDA when there is a GPU. Absolute times cannot be compared
# across machines; the speed-up (Monoloco as published / DRF batched, same group of the same run)
# can.

# %%
# NBVAL_IGNORE_OUTPUT
b1 = min(P.timing.batch_sizes)
groups = [("cpu", t) for t in P.timing.threads] + [(d, claim_threads) for d in devices if d != "cpu"]
side = pd.DataFrame({"paper (GTX 1080), ms": [TIMING_MS["monoloco"], TIMING_MS["drf"], np.nan],
                     "paper speed-up": [1.0, TIMING_SPEEDUP, np.nan]},
                    index=["Monoloco (published, S sequential passes)", "DRF (S batched decoder samples)",
                           "DRF (deterministic pass)"])
for dev, t in groups:
    col = f"ours {dev} {t} thr, ms/frame"
    side[col] = [lookup(table, "pedestrians", "monoloco", "published", b1, t, dev),
                 lookup(table, "pedestrians", "drf", "batched", b1, t, dev),
                 lookup(table, "pedestrians", "drf", "no_sampling", b1, t, dev)]
    side[f"ours {dev} {t} thr, speed-up"] = [1.0, side[col].iloc[0] / side[col].iloc[1], np.nan]
side.round(3)

# %% [markdown]
# ## Claim C6 and the targets
# The claim's speed-up is measured at batch 1 on CPU with the **smallest** thread count of
# `timing_threads`: a batch-1 step of these small networks is a chain of tiny operators that
# ATen does not split across threads (below its grain size), so extra threads cannot make it
# faster and only expose it to contention from other processes; one thread is also the most
# reproducible setting on a shared machine. The other thread counts and CUDA are reported beside
# it. The rule is two-sided: the paper's claim is a factor of 2.93, so the speed-up must lie within
# 15 % of it either way to reproduce it. The ratio of two medians cannot say whether a difference
# from that band is larger than the timings' own noise (four cold runs on one machine model gave
# 3.26-3.49x against a band ending at 3.37x), so the claim is judged on the pair alone, timed in
# `timing_paired_rounds` interleaved rounds (`drfkit.study.bench.paired_rounds`): one ratio per
# round, pooled as the geometric mean with its 95 % interval. Reproduced if the interval lies inside
# the band, a different factor if wholly outside it (faster or slower, said which), at the band's
# edge if it straddles an end. Targets of this book: DRF's S-sample prediction ≥ 3× faster per
# frame than Monoloco as published at batch 1, and at most 1.25× DRF's own deterministic pass.

# %%
# NBVAL_IGNORE_OUTPUT
from drfkit.study.bench import paired_rounds

rounds = cached(P.profile, paired_rounds, P.uncertainty.n_samples, P.timing.paired_rounds, claim_threads, "cpu",
                seed=P.seeds[0], timing=True)
save_table(P.profile, "timing_c6_rounds", rounds)
print(f"{len(rounds)} paired rounds: Monoloco / DRF per round, median {rounds['ratio'].median():.2f}x, "
      f"interquartile {rounds['ratio'].quantile(0.25):.2f}-{rounds['ratio'].quantile(0.75):.2f}x")

# %%
# NBVAL_IGNORE_OUTPUT
speedup = speedup_vs_monoloco(table, b1, claim_threads, "cpu")
# judged from tables/timing.csv (written above), as `python -m drfkit claims` judges it again later
row = judge.write(P, ["C6"]).set_index("id").loc["C6"]
print(f"C6: {row['ours']} -> {row['verdict']} ({os.cpu_count()} cores)")


def ms(model, mode, threads=claim_threads, batch=b1, device="cpu", column="median_ms_per_frame"):
    return lookup(table, "pedestrians", model, mode, batch, threads, device, column)


overhead = ms("drf", "batched") / ms("drf", "no_sampling")
mono_step = ms("monoloco", "published") / P.uncertainty.n_samples
SPEEDUP_TARGET, OVERHEAD_TARGET = claims.TIMING_SPEEDUP_TARGET, claims.SAMPLING_OVERHEAD_TARGET  # why: drfkit.study.claims
checks = [(f"DRF (S samples) >= {SPEEDUP_TARGET:g}x faster than Monoloco as published, batch 1",
           speedup >= SPEEDUP_TARGET, f"{speedup:.2f}x"),
          (f"DRF S-sample prediction <= {OVERHEAD_TARGET:g}x its deterministic pass, batch 1",
           overhead <= OVERHEAD_TARGET, f"{overhead:.2f}x")]
for name, ok, value in checks:
    print(f"[{'met' if ok else 'MISSED'}] {name}: {value}")

# %% [markdown]
# ### Why, in numbers from this run
# The cell below explains each result from the measured components: the cost of one Monoloco
# pass, of DRF's deterministic step (encoder + filter step + decoder), and of what sampling adds.

# %%
# NBVAL_IGNORE_OUTPUT
det, bat = ms("drf", "no_sampling"), ms("drf", "batched")
seq, naive = ms("drf", "sequential"), ms("drf", "naive")
mono_det, mono_bat = ms("monoloco", "no_sampling"), ms("monoloco", "batched")
print(f"At batch {b1} on CPU with {claim_threads} thread(s): one Monoloco dropout pass costs about "
      f"{mono_step:.3f} ms ({P.uncertainty.n_samples} of them: {ms('monoloco', 'published'):.3f} ms), while DRF's "
      f"deterministic step costs {det:.3f} ms, i.e. {det / mono_det:.1f}x a deterministic Monoloco pass "
      f"({mono_det:.3f} ms): the Kalman step (Cholesky solve, Joseph-form update) and the transition LSTM "
      f"are many small operators. Sampling changes DRF's time by {bat - det:+.3f} ms ({overhead:.2f}x its "
      f"deterministic pass; differences below the IQR {ms('drf', 'batched', column='iqr_ms_per_frame'):.3f} ms "
      f"are noise), because only the decoder is sampled, in one call. The speed-up over "
      f"Monoloco as published is therefore about {P.uncertainty.n_samples} x {mono_step:.3f} / {bat:.3f} = "
      f"{speedup:.2f}x.")
print(f"Where the gain comes from: sampling the decoder in one call instead of {P.uncertainty.n_samples} calls saves "
      f"{seq - bat:.3f} ms ({seq / bat:.1f}x); running the filter once instead of in each of the "
      f"{P.uncertainty.n_samples} passes saves {naive - seq:.3f} ms ({naive / seq:.1f}x). Monoloco batched "
      f"({mono_bat:.3f} ms) would be {ms('monoloco', 'published') / mono_bat:.1f}x faster than Monoloco as "
      f"published, and then {'still slower than' if mono_bat > bat else 'as fast as or faster than'} DRF "
      f"({mono_bat / bat:.2f}x DRF's time): "
      + ("most of the speed-up comes from batching the samples, which Monoloco could do too; where the "
         "dropout sits matters less at this batch." if mono_bat / bat < 1.5 else
         "where the dropout sits matters beyond batching: even batched, Monoloco samples every layer."))
if speedup < SPEEDUP_TARGET:
    print(f"Target 1 missed: DRF's deterministic step alone ({det:.3f} ms) is "
          f"{ms('monoloco', 'published') / det:.2f}x cheaper than Monoloco's {P.uncertainty.n_samples} passes, so no "
          f"sampling scheme could reach {SPEEDUP_TARGET:g}x here.")
if overhead > OVERHEAD_TARGET:
    print(f"Target 2 missed: sampling adds {bat - det:.3f} ms to a {det:.3f} ms step; at batch {b1} this is "
          f"the fixed cost of the extra operators (mask draw, {P.uncertainty.n_samples}-fold readout, mixture moments), "
          f"not arithmetic.")
high_t = max(P.timing.threads)
if high_t != claim_threads:
    slow = ms("drf", "batched", high_t) / bat
    print(f"With {high_t} threads DRF's batch-{b1} prediction takes {slow:.2f}x its {claim_threads}-thread "
          f"time. The machine has {os.cpu_count()} cores and its 1-minute load average was "
          f"{load_before:.1f} before and {load_after:.1f} after the benchmark (max during it "
          f"{table['load_1min'].max():.1f}): "
          + ("with more runnable processes than cores, a multi-threaded operator waits for a descheduled "
             "thread, so these numbers measure contention, not the model."
             if table["load_1min"].max() > (os.cpu_count() or 1) else
             "the cores were not oversubscribed, so this is the cost of thread synchronisation on tiny "
             "operators."))
if "cuda" in devices:
    print(f"On CUDA at batch {b1}: DRF {ms('drf', 'batched', device='cuda'):.3f} ms vs Monoloco as published "
          f"{ms('monoloco', 'published', device='cuda'):.3f} ms per frame "
          f"({speedup_vs_monoloco(table, b1, claim_threads, 'cuda'):.2f}x).")
big = max(P.timing.batch_sizes)
print(f"At batch {big} (CPU, {claim_threads} thread(s)) the per-frame costs are DRF "
      f"{ms('drf', 'batched', batch=big):.4f} ms and Monoloco as published "
      f"{ms('monoloco', 'published', batch=big):.4f} ms ({speedup_vs_monoloco(table, big, claim_threads, 'cpu'):.2f}x): "
      f"with many pedestrians per call the arithmetic, not the operator count, decides.")

# %% [markdown]
# **Reading these numbers.** Batch-1 latencies on CPU are dominated by the fixed cost of each
# operator call (microseconds to tens of microseconds in eager PyTorch), so they count operators
# more than FLOPs. Small batches on a GPU are likewise bound by per-kernel launch cost, but the
# balance between operator count and arithmetic differs between machines, so only the ratios,
# not the milliseconds, are comparable with the paper's — and even the ratios only roughly, since
# the paper does not state its batch (pedestrians per call). The `load_1min` column of the table records how busy the machine was: in
# the book's own runs the two cores were shared with other jobs, so the numbers are noisy, and
# thread counts above the number of idle cores are not meaningful.

# %% [markdown]
# ## Training speed: the DRF's epoch against no_dynamics'
# One optimisation step (forward, loss, backward) of each model on the same batch of 50 × T frames,
# measured in one run in interleaved rounds (`drfkit.methods.timing.training_step_times`: each round times
# every model in turn, so a slow spell of the machine hits all of them); seconds per epoch follow
# from the number of batches, and `ratio_to_no_dynamics` is the median of the per-round ratios
# (at least 15 rounds; `ratio_to_no_dynamics_iqr` is their interquartile range). The target is a
# DRF epoch at most 1.5× a no_dynamics epoch, at the notebook's thread count. A rerun on the same
# machine with the same code reuses these timings and the deterministic studies below
# (`drfkit.book.measurements`: each cell says when it measured; `make reproduce REMEASURE=1` measures
# again). In training the DRF's
# recursion runs as one autograd node with a hand-written backward (`drfkit.models.recursion`; the
# tests check it against autograd); `drf_per_step` is the same model differentiated step by step
# by autograd, for comparison.
#
# A time ratio mixes two things: how much arithmetic each step does, and how fast it runs. So each
# step's arithmetic is also counted (`drfkit.methods.timing.count_flops`: the matrix products and
# convolutions of forward and backward, as `torch.utils.flop_counter` counts them, and the CPU
# LSTM layer by a formula drfkit adds; not the filter's Cholesky factor and inverse, nor
# elementwise ops, so `gflop` is a lower bound of the work). `flop_ratio_to_no_dynamics`
# is the time ratio the DRF would have if it ran its counted arithmetic at the no_dynamics step's
# rate. The DRF does all of the no_dynamics step's work (encoder, heads, decoder) plus the
# recursion: per step and sequence, two LSTM cells, a 64 → 930 head and the filter's batched 30 × 30
# products, forward and backward. Where that ratio exceeds 1.5, the target needs the recursion --
# 74 sequential steps of small products -- to run at a higher arithmetic rate than the encoder's
# convolutions over all 50 × T frames at once.

# %%
# NBVAL_IGNORE_OUTPUT
import torch

from drfkit.methods.timing import epoch_times, recursion_scaling, training_step_times
from drfkit.report.writers import epoch_times_line, recursion_scaling_line
from drfkit.study import studies

train, val = studies.pendulum_data(P, "train"), studies.pendulum_data(P, "val")
batch = min(50, len(train))
configs = {k: studies.model_config("pendulum", k) for k in ["no_dynamics", "lstm", "drf"]}
speed = cached(P.profile, training_step_times, configs | {"drf_per_step": configs["drf"]}, train.inputs[:batch],
               train.targets[:batch], n_batches_per_epoch=int(np.ceil(P.pendulum.train_sequences / batch)),
               min_run_time=0.5, min_rounds=15, model_attrs={"drf_per_step": {"whole_sequence": False}},
               with_flops=True, timing=True)
save_table(P.profile, "pendulum_training_speed", speed)
drf_row = speed.set_index("model").loc["drf"]
nd_row = speed.set_index("model").loc["no_dynamics"]
print(f"a DRF training step costs {drf_row['ratio_to_no_dynamics']:.2f}x a no_dynamics step (per-round IQR "
      f"{drf_row['ratio_to_no_dynamics_iqr']:.2f}) at {int(speed['threads'].iloc[0])} thread(s); "
      f"target <= 1.5x: {'met' if drf_row['ratio_to_no_dynamics'] <= 1.5 else 'not met'}")
print(f"counted arithmetic: {drf_row['gflop']:.2f} against {nd_row['gflop']:.2f} GFLOP per step, "
      f"{drf_row['flop_ratio_to_no_dynamics']:.2f}x; run at {drf_row['gflop_per_s']:.1f} against {nd_row['gflop_per_s']:.1f} GFLOP/s")
print(f"meeting 1.5x needs the DRF step at >= {drf_row['flop_ratio_to_no_dynamics'] / 1.5:.2f}x the no_dynamics "
      f"step's arithmetic rate; it runs at {drf_row['gflop_per_s'] / nd_row['gflop_per_s']:.2f}x")
speed

# %% [markdown]
# ### Whole epochs
# The target is stated per epoch, and an epoch is more than its steps: batching the uint8 images,
# clipping and Adam, the validation loss (the DRF's through its per-step inference loop) and two
# checkpoint writes. `drfkit.methods.timing.epoch_times` trains a fresh model of each kind for one whole
# epoch with the training loop itself (`drfkit.methods.train.train_model`, checkpoints into a temporary
# folder), in an order rotated per round, three rounds; the ratio is again the median of the
# per-round ratios.

# %%
# NBVAL_IGNORE_OUTPUT
epochs = cached(P.profile, epoch_times, configs, train, val,
                {k: studies.train_config(P, "pendulum", k, P.seeds[0]) for k in configs}, rounds=3, timing=True)
save_table(P.profile, "pendulum_epoch_times", epochs)
print(epoch_times_line(epochs).replace("**", ""))
epochs

# %% [markdown]
# ### Per-call cost or arithmetic?
# The recursion runs hundreds of small ops per filter step, so part of its time is the cost of
# issuing them (interpreter, dispatcher, LAPACK's per-call setup) and does not grow with the batch.
# `drfkit.methods.timing.recursion_scaling` times the recursion alone (forward and backward) at half, one
# and two times the batch, in the same interleaved run as a training step of each model, and fits
# a line t(b) = fixed + per-sequence · b. Its intercept is the per-call cost; its slope the work of
# one more sequence with torch's kernels as they run now. `floor_ratio` removes the intercept from
# the DRF step: the step ratio a recursion with no per-call cost at all, calling the same kernels,
# would reach. It is measured at one thread and at the notebook's thread count. Where it stays
# above 1.5, trimming overhead, in Python or in a compiled loop, cannot meet the target, and only
# faster kernels for the small products and factorisations could; where it is below, a loop with
# no per-call cost at all could, by no more than the margin it shows.

# %%
# NBVAL_IGNORE_OUTPUT
scaling = pd.concat([cached(P.profile, recursion_scaling, configs["no_dynamics"], configs["drf"], train.inputs[:batch],
                            train.targets[:batch], min_run_time=0.5, min_rounds=15, threads=n, timing=True)
                     for n in sorted({1, torch.get_num_threads()})], ignore_index=True)
save_table(P.profile, "pendulum_recursion_scaling", scaling)
fig, axes = new_figure(width=4.8)
ax = axes[0, 0]
for n, part in scaling[scaling["part"] == "recursion"].groupby("threads"):
    line, = ax.plot(part["batch"], 1e3 * part["median_s"], "o", label=f"{n} thread(s)")
    grid = np.linspace(0, part["batch"].max(), 50)
    ax.plot(grid, 1e3 * (part["fixed_s"].iloc[0] + part["per_sequence_s"].iloc[0] * grid), "--", color=line.get_color())
ax.axvline(batch, color="gray", lw=0.8, label="training batch")
ax.set(xlabel="sequences in the batch", ylabel="recursion, forward + backward (ms)", xlim=(0, None), ylim=(0, None),
       title=f"DRF recursion over {train.inputs.shape[1]} frames")
ax.legend()
save_figure(P.profile, "pendulum_recursion_scaling", fig)
print(recursion_scaling_line(scaling).replace("**", ""))
scaling.round(4)

# %%
_ = timer.finish()
