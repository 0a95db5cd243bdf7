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
# # A cubesat on reaction wheels with a late star tracker
#
# The shipped `cubesat_wheels` scenario: a 12U cubesat, τ = 0.2 s, three orthogonal wheels of 5 mN m and
# 20 mN m s at 6000 rpm. The PD gains alone drive the wheels into their speed limit on a 90° slew; the
# rate-limited steering law designed for the wheels (`design_for_actuator`) keeps the commanded momentum
# within what the wheels hold.

# %%
# %matplotlib inline
from dataclasses import replace

from mrpctl import plots
from mrpctl.design.actuator import design_for_actuator
from mrpctl.scenario import load_scenario, resolve_scenario

scenario = load_scenario(resolve_scenario("cubesat_wheels"))
pd = scenario.simulate()
print(pd)

# %%
plots.plot_wheels(pd)

# %% [markdown]
# The design for the wheels and an envelope of initial rates up to 0.05 rad/s (any attitude): the law's rate
# limit comes from the torque the wheels can always give and from the momentum they hold.

# %%
design = design_for_actuator(scenario.spacecraft, scenario.tau, scenario.wheels, max_rate=0.05, settling_time=120.0)
print(design)
steered = replace(scenario, K=design.K, law=design.law).simulate()
print(f"PD alone:      settled at {pd.settling_time:.1f} s")
print(f"steering law:  settled at {steered.settling_time:.1f} s")

# %%
plots.plot_wheels(steered)
