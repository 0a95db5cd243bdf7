"""Export the paper's closed loop and call it back from Python through CasADi alone.

Run with ``python examples/export_and_call.py``. It writes the export to a temporary
folder, loads ``step`` and ``controller`` from the ``.casadi`` files
(``casadi.Function.load``) and from the shared library (``casadi.external``), and runs
the paper's loop for 1 s at 1 kHz with a ring buffer of d delayed measurements, as
``examples/export_harness.c`` does in C (here without a switching rule). Only the
export step needs mrpctl; the rest runs with casadi and numpy.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import casadi
import numpy as np

from mrpctl import export, paper
from mrpctl.switching import NoSwitching


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="mrpctl-export-") as tmp:
        folder = Path(tmp) / "paper"
        result = export(
            paper.SPACECRAFT,
            paper.GAIN,
            folder,
            tau=paper.TAU,
            rule=NoSwitching(),
            rate=paper.MEASUREMENT_RATE,
        )
        print(result)
        manifest = json.loads((folder / "manifest.json").read_text())
        d = manifest["parameters"]["delay_samples"]

        # From the serialized Functions (any platform with casadi) ...
        step = casadi.Function.load(str(folder / "step.casadi"))
        controller = casadi.Function.load(str(folder / "controller.casadi"))
        print(step)
        print(controller)
        # ... or from the compiled library (C symbols carry the prefix "mrpctl_").
        if result.library is not None:
            step = casadi.external("mrpctl_step", str(result.library))
            controller = casadi.external("mrpctl_controller", str(result.library))
            print(f"using {result.library.name}: {step}")

        x = np.array(paper.INITIAL_STATE)
        buffer = [x.copy() for _ in range(d)]  # m_{-d}, ..., m_{-1} = x0 (constant history)
        for k in range(1000):
            u = controller(x_meas=buffer[k % d])["u"]  # u_k = K m_{k-d}, named ports
            buffer[k % d] = x.copy()  # record m_k (no switching rule here)
            x = np.array(step(x, u)).ravel()  # x_{k+1}: RK4 over 1 ms
        sigma, omega = x[0:3], 4.0 * x[3:6]
        print(f"t = 1 s: sigma = {sigma}, omega = {omega} rad/s")


if __name__ == "__main__":
    main()
