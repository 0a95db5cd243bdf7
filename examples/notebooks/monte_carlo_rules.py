# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Monte Carlo of the switching rules (the notebook of `examples/monte_carlo_rules.py`)
#
# The paper's spacecraft, gains and τ = 0.5 s; tumbling initial states (random axes, angles of
# 160–179°, rates of 0.5–1.2 rad/s towards 180°), each rule on the same states. Fewer and shorter
# runs than the script so that the notebook runs in seconds.

# %%
# %matplotlib inline
import numpy as np

from mrpctl import BoundaryLayer, DelayAware, NoSwitching, OnCurrent, OnDelayed, paper, plots, simulate_batch
from mrpctl.scenario import tumbling_states

COUNT, T_FINAL, LATE = 24, 20.0, 5.0  # runs, s, s
x0 = tumbling_states(COUNT, seed=1)
rules = (NoSwitching(), OnCurrent(), OnDelayed(), BoundaryLayer(eps=0.005), DelayAware())
batches = {}
for rule in rules:
    batch = simulate_batch(paper.SPACECRAFT, paper.GAIN, x0, tau=paper.TAU, rule=rule, t_final=T_FINAL)
    batches[type(rule).__name__] = batch
    late = np.nan_to_num(batch.last_switch_time, nan=-np.inf) > T_FINAL - LATE
    median = np.median(batch.switch_count)
    print(f"{type(rule).__name__:<14} still switching {np.mean(late):4.0%}, median switches {median:g}")

# %% [markdown]
# The state-side rule on the delayed measurement keeps switching; the delay-aware rule switches once
# or twice per run. Independent runs are distributions, not a line over run index:

# %%
plots.plot_monte_carlo(batches["OnDelayed"], title="OnDelayed: switch counts")
