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
# # Design, certify and simulate a small satellite
#
# J = diag(12, 15, 9) kg m², measurement delay τ = 0.2 s: the fastest critically damped PD
# gains the order-2 LMI certifies, backed off to 70 % of that bandwidth, then a tumble
# through 180° with the delay-aware switching rule, and the loop in python-control terms.

# %%
# %matplotlib inline
import control
import numpy as np

from mrpctl import DelayAware, Spacecraft, mrp, plots, simulate
from mrpctl.design import linearized_loop, pd_gains, synthesize_pd
from mrpctl.interop import delayed_loop, loop_margins
from mrpctl.model import state

TAU = 0.2  # s
sc = Spacecraft([12, 15, 9])
fastest = synthesize_pd(sc, TAU, zeta=1.0, order=2)
gains = pd_gains(sc, zeta=1.0, omega_n=0.7 * fastest.gains.omega_n)
loop = linearized_loop(sc, gains.K)
print(fastest)
print(loop.certify(TAU, order=2))
print(loop_margins(sc, gains.K))

# %% [markdown]
# The Padé-closed loop's rightmost pole, against the exact margin.

# %%
closed = delayed_loop(sc, gains.K, tau=TAU).pade(order=6)
print(f"rightmost pole real part {np.max(control.poles(closed).real):.4f} 1/s")

# %%
sigma0 = mrp.from_principal_rotation([0.3, -0.5, 0.8], np.radians(178.0))
x0 = state(sigma0, 1.0 * sigma0 / np.linalg.norm(sigma0))  # 1 rad/s towards 180 deg
run = simulate(sc, gains.K, x0, tau=TAU, rule=DelayAware(), t_final=20.0)
print(run)
plots.plot_response(run)
