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
# # The paper's chatter, and the rule that avoids it
#
# Samiei & Butcher's spacecraft (J = diag(140, 100, 80) kg m²) tumbles through the MRP
# switching point while its attitude is measured with a 0.5 s delay. Switching on the
# delayed measurement chatters; mrpctl's delay-aware rule switches twice.

# %%
# %matplotlib inline
import matplotlib.pyplot as plt  # the notebook's backend shows the figures; mrpctl selects none

from mrpctl import DelayAware, OnDelayed, paper, plots, simulate
from mrpctl.design import linearized_loop

print(linearized_loop(paper.SPACECRAFT, paper.GAIN).delay_margin())

# %%
runs = {
    rule.__class__.__name__: simulate(
        paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, tau=paper.TAU, rule=rule, t_final=10.0
    )
    for rule in (OnDelayed(), DelayAware())
}
for name, run in runs.items():
    print(f"{name:<10} {run.switch_count:5d} switches, converged: {run.converged}")

# %% [markdown]
# The response under switching at |σ(t − τ)| = 1: the red ticks are switches.

# %%
plots.plot_response(runs["OnDelayed"])

# %% [markdown]
# The last 0.2 s, one step per 1 ms sample: σ₁ jumps between the sets.

# %%
fig, ax = plt.subplots(figsize=(8, 3), layout="constrained")
plots.plot_attitude(runs["OnDelayed"], window=(9.8, 10.0), ax=ax)
plt.show()

# %%
plots.plot_response(runs["DelayAware"])
