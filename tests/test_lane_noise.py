"""The lanes' own noise (mrpctl/engines/lanes_own.c): the bound of sure acceptance of its 8-lane first attempt, and
the lanes' numbers at widths whose lanes take the 8-lane path in two groups (16) or the lane-by-lane loop (4).

The bound table ``mrpctl_zig_sure`` is checked against the ziggurat's X recomputed by the NumPy reference
(``tests/noise_reference.py``, independent of the C literals): every uniform below an entry is accepted by the first
attempt of each layer of its group (x = m X[i] 2^-53 < X[i + 1], in float64 as the generator computes it), and the
entry is the least such bound over the group. The numbers themselves are compared bit for bit through whole runs
(the same dispersed batch as ``tests/test_lanes_per_run_models.py``) against the scalar engine, whose noise is
``noise.c``'s loop run by run.
"""

from __future__ import annotations

import re
from importlib import resources

import noise_reference as reference
import pytest
from lane_assertions import assert_same_bits, scalar_batch
from test_lanes_per_run_models import COMMON, _case

from mrpctl import simulate_batch
from mrpctl._compile import find_compiler
from mrpctl.engines import lanes as lane_engines

GROUP = 8  # layers per entry of mrpctl_zig_sure (the entry of layer i is i >> 3)


def _sure_table() -> list[float]:
    source = resources.files("mrpctl.engines").joinpath("lanes_own.c").read_text(encoding="utf-8")
    body = re.search(r"mrpctl_zig_sure\[32\][^{]*\{([^}]*)\}", source)
    assert body is not None
    return [float.fromhex(text) for text in re.findall(r"0x[0-9a-f.]+p[+-]\d+", body.group(1))]


def _least_rejected(scale: float, limit: float) -> int:
    """The least integer m in [0, 2^53] with float64 m * scale >= limit (2^53: none below it)."""
    low, high = -1, 2**53  # m = low is accepted (or -1), m = high rejected (or 2^53)
    while high - low > 1:
        middle = (low + high) // 2
        if float(middle) * scale < limit:
            low = middle
        else:
            high = middle
    return high


def test_the_bound_of_sure_acceptance_is_sound_and_the_least_over_each_group():
    x, _ = reference._ziggurat_tables()
    sure = _sure_table()
    assert len(sure) == 256 // GROUP
    for group, bound in enumerate(sure):
        assert bound == int(bound) and 1 <= bound < 2**53, group
        layers = [i for i in range(group * GROUP, (group + 1) * GROUP) if i != 255]  # 255 accepts nothing
        for i in layers:
            scale = x[i] * 2.0**-53  # exact (a power of two), the generator's mrpctl_zig_xs[i]
            # the largest uniform below the bound is accepted, so every smaller one is (the product is monotone)
            assert float(int(bound) - 1) * scale < x[i + 1], (group, i)
        assert int(bound) == min(_least_rejected(x[i] * 2.0**-53, x[i + 1]) for i in layers), group
    # the bound accepts ~98 % of the first attempts at once (the rest are decided exactly after the block)
    sure_fraction = sum(sure[i // GROUP] * 2.0**-53 for i in range(255)) / 256
    assert 0.975 < sure_fraction < 0.9851


@pytest.mark.skipif(find_compiler() is None, reason="the lane engine needs a C compiler")
@pytest.mark.parametrize("width", [16, 4])
def test_own_noise_on_other_widths_equals_the_scalar_engine_bit_for_bit(width, monkeypatch):
    case = _case()
    scalar = scalar_batch(**case, **COMMON, threads=1)
    built: list[tuple[int, bool]] = []
    build = lane_engines.lane_engine

    def at_width(*args, **kwargs):
        engine = build(*args, **kwargs, width=width)
        built.append((engine.width, engine.own_streams))
        return engine

    monkeypatch.setattr(lane_engines, "lane_engine", at_width)
    lanes = simulate_batch(**case, **COMMON, threads=2)
    assert built == [(width, True)]  # one lane group, on the lanes at that width, each lane its own streams
    assert_same_bits(lanes, scalar)
