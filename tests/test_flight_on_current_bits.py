"""What README states about Hysteretic(0) against OnCurrent: σ, ω bit for bit, u equal up to the sign of zero."""

import numpy as np

from mrpctl import OnCurrent, paper, simulate
from mrpctl.flight import Hysteretic


def test_hysteretic_zero_equals_on_current_up_to_the_sign_of_zero():
    common = dict(tau=0.5, t_final=1.5)
    plain = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=OnCurrent(), **common)
    flight = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=Hysteretic(0.0), **common)
    assert flight.sigma.tobytes() == plain.sigma.tobytes()
    assert flight.omega.tobytes() == plain.omega.tobytes()
    assert np.array_equal(flight.u, plain.u)  # == : -0 == +0
    differs = np.signbit(flight.u) != np.signbit(plain.u)
    assert np.all(plain.u[differs] == 0.0)  # the only bit differences are signs of zero
    assert flight.u.tobytes() != plain.u.tobytes()  # and there are some: "bit for bit" would be false
