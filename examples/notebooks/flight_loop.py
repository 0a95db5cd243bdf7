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
# # The loop as flown: controller-side set selection with hysteresis, noise, limits, jitter
#
# The flight software chooses the MRP set from the delayed, noisy star-tracker attitude
# (`Hysteretic`, Mayhew–Sanfelice–Teel). With 0.01 rad of attitude noise and no hysteresis the
# controller changes set on noise near Φ = 180°; with α = 1.2 it changes once.

# %%
# %matplotlib inline
from mrpctl import paper, plots, simulate
from mrpctl.flight import ActuatorModel, DelayModel, Hysteretic, SensorModel

sensor = SensorModel(attitude_noise=0.01, rate_noise=1e-4, seed=1)
options = dict(tau=0.5, t_final=20.0, sensor=sensor, delay=DelayModel.jitter(0.45, 0.5, seed=2))
no_hysteresis = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=Hysteretic(0.0), **options)
hysteresis = simulate(
    paper.SPACECRAFT,
    paper.GAIN,
    paper.INITIAL_STATE,
    rule=Hysteretic.from_alpha(1.2),
    actuator=ActuatorModel(u_max=20.0),
    **options,
)
print(f"no hysteresis: {no_hysteresis.switch_count} set changes")
saturated = hysteresis.saturated_fraction
print(f"alpha = 1.2:   {hysteresis.switch_count} set change, saturated {saturated:.1%} of the samples")

# %%
plots.plot_response(hysteresis)
