"""Where the flight sample's time goes, counted: instructions per sample of each variant of ``bench/flight.py``.

The CPU-time table of ``bench/flight.py`` moves by ±0.2 in its ratios between two runs on a shared host
(other virtual machines; measured on the development host: the same binary from 19.5 to 40 ns per six
normals), which is more than most changes to the flight sample are worth. Instructions executed are
exact and repeatable: each variant of ``bench/flight.py`` (``FLIGHT``, and the plain ``OnCurrent`` run)
runs once in a child process under valgrind's cachegrind (``--branch-sim=yes``), and the table gives,
per sample of a ``T`` s run at 1 kHz, the instructions, the conditional branches and the mispredicted
ones (cachegrind's simple predictor model) of the engine library (the sample function, the driver, the
random streams) and of libm (tan, sqrt, exp, log called from it), with the ratio of instructions to the
plain run. On the development host the time per sample tracked the instructions (≈ 8.5 per ns), so the
ratio of instructions is the CPU-time ratio without the host's noise.

Run: ``.venv/bin/python bench/flight_instructions.py [T] [word ...]`` (default 30 s of simulated time per
run; about a minute per variant under valgrind; words: only the variants whose label has one, e.g.
``all``). Needs ``valgrind`` and ``cg_annotate`` on the PATH (not a dependency of mrpctl; the script
says so and exits 2 without them).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

_CHILD = """
import sys
sys.path.insert(0, {bench!r})
import flight as bench
from mrpctl import OnCurrent, paper, simulate

label, t_final = sys.argv[1], float(sys.argv[2])
rule, options = (OnCurrent(), {{}}) if label == "plain (OnCurrent)" else bench.FLIGHT[label]
simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, tau=bench.TAU, rule=rule, t_final=t_final,
         rate=bench.RATE, keep_every=None, **options)
"""
_PERCENT = re.compile(r"\([^)]*\)")
# libm's functions the engine calls (glibc's sources ./math/... when its debug information is installed, else
# ???); not frexp & co. of Python's start. A first version matched "libm" in the line, which is in neither form: it
# counted no tan at all (49 instructions a sample of the noisy sensor).
_LIBM = re.compile(r"(\s\./math/\S*|\?\?\?):(__)?(tan|sin|cos|exp|log|sqrt|atan2?|hypot)(_\w+)?(@@GLIBC[\w.]*)?\s*$")


def count(label: str, t_final: float, folder: Path) -> tuple[float, float, float]:
    """(instructions, conditional branches, mispredicted branches) per sample of one variant."""
    script = folder / "child.py"
    script.write_text(_CHILD.format(bench=str(Path(__file__).resolve().parent)))
    out = folder / "cachegrind.out"
    environment = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    command = ["valgrind", "--tool=cachegrind", "--cache-sim=no", "--branch-sim=yes", f"--cachegrind-out-file={out}"]
    subprocess.run(
        [*command, sys.executable, str(script), label, str(t_final)],
        env=environment,
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    report = subprocess.run(["cg_annotate", "--threshold=0.0001", str(out)], check=True, capture_output=True, text=True)
    totals = [0, 0, 0]
    for line in report.stdout.splitlines():
        if "???:mrpctl_" not in line and not _LIBM.search(line):  # the engine library (no debug info) and libm
            continue
        fields = _PERCENT.sub(" ", line).split()
        if len(fields) >= 4 and all(re.fullmatch(r"[\d,]+", field) for field in fields[:3]):
            for i in range(3):
                totals[i] += int(fields[i].replace(",", ""))
    samples = round(t_final * 1000.0) + 1
    return totals[0] / samples, totals[1] / samples, totals[2] / samples


def main() -> int:
    if shutil.which("valgrind") is None or shutil.which("cg_annotate") is None:
        print("bench/flight_instructions.py needs valgrind and cg_annotate on the PATH", file=sys.stderr)
        return 2
    t_final = float(sys.argv[1]) if len(sys.argv) > 1 else 30.0
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import flight as bench

    labels = ["plain (OnCurrent)", *bench.FLIGHT]
    if len(sys.argv) > 2:  # only the variants whose label contains one of these words (and the plain run)
        labels = [labels[0], *(label for label in labels[1:] if any(word in label for word in sys.argv[2:]))]
    print(
        f"paper case, {t_final:g} s at 1000 Hz, keep_every=None; per sample, the engine library and libm (cachegrind)"
    )
    print(f"{'variant':42s} {'instr':>8s} {'branches':>9s} {'mispred':>8s} {'x plain':>8s}")
    plain = None
    with tempfile.TemporaryDirectory() as folder:
        for label in labels:
            instructions, branches, missed = count(label, t_final, Path(folder))
            plain = instructions if plain is None else plain
            print(f"{label:42s} {instructions:8.0f} {branches:9.1f} {missed:8.3f} {instructions / plain:8.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
