"""The engines that run the closed loop's samples (built by `mrpctl.loop`) over a horizon.

* `mrpctl.engines.scalar`: one run per call; the sample with its metric accumulators compiled with the
  C horizon driver ``scalar_driver.c`` (and the noise streams of ``noise.c``), cached on disk;
* `mrpctl.engines.lanes`: W runs per call, W-lane C emitted from the same sample's instructions
  (``lanes_driver.c``), bit-identical per lane to the scalar engine;
* `mrpctl.engines.vm`: the same sample in CasADi's virtual machine, when no C compiler is found;
* `mrpctl.engines.stats`, `common`, `libm`: the statistics vector, the per-run buffers and output,
  the host libm's fmin/fmax forms that every engine shares.

Which engine runs a call is decided in two places only: `mrpctl.engines.scalar.engine` returns the
compiled engine or, without a compiler, the virtual machine; `mrpctl.simulate_batch` sends metrics-only
batches to the lanes (`mrpctl.simulation`).
"""

from __future__ import annotations

__all__: list[str] = []
