"""W-lane C emitted from the instruction list of a pure SX Function, bit-identical per lane to CasADi's
scalar C (the code generator of the lane engine, `mrpctl.engines.lanes`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import casadi as ca

from mrpctl._validation import integer
from mrpctl.engines.libm import min_max_forms
from mrpctl.errors import CodegenError, SpecificationError

__all__ = ["LaneProgram", "emit_lanes"]

# ------------------------------------------------------------------ the operations
# Each entry: the C expression of one lane, as CasADi 3.8's code generator writes it for a
# scalar (casadi/core/calculus.h, casadi_math<T>::print and the casadi_* helpers). The
# comparison and logic operators give 0/1 as ints in CasADi's C, converted to double on
# assignment; ``c ? ...`` tests c != 0 (NaN is true), as in C.
_VECTOR_OPS: dict[int, str] = {
    ca.OP_ASSIGN: "{0}",
    ca.OP_ADD: "({0}+{1})",
    ca.OP_SUB: "({0}-{1})",
    ca.OP_MUL: "({0}*{1})",
    ca.OP_DIV: "({0}/{1})",
    ca.OP_NEG: "(-{0})",
    ca.OP_TWICE: "(2.*{0})",
    ca.OP_INV: "(1./{0})",
    ca.OP_SQ: "({0}*{0})",  # casadi_sq(x) { return x*x; }
    ca.OP_SQRT: "sqrt({0})",  # vectorised with -fno-math-errno (sqrtpd is correctly rounded, as sqrtsd)
    ca.OP_FABS: "fabs({0})",
    ca.OP_COPYSIGN: "copysign({0},{1})",
    ca.OP_SIGN: "L_SELECT(L_MASK({0}<0.), -1., L_SELECT(L_MASK({0}>0.), 1., {0}))",  # x<0 ? -1 : x>0 ? 1 : x
    ca.OP_IF_ELSE_ZERO: "mrpctl_real(mrpctl_bits({1}) & L_MASK({t0}))",  # (c?x:0): x, or +0.0
}
# Comparisons and logic: CasADi's C gives the int 0/1 (as double 1.0 or +0.0). The lanes keep
# that int condition m as well, so that a consumer in the same loop tests "x != 0" as m (the
# value is exactly 0.0 or 1.0, so the two tests agree), and widen it to a bit mask (L_MASK) only
# where a selection uses it: gcc then keeps the conditions in mask registers (AVX-512) and
# selects by blends. {t0}/{t1}: the operand's condition.
_MASK_OPS: dict[int, str] = {
    ca.OP_LT: "({0}<{1})",
    ca.OP_LE: "({0}<={1})",
    ca.OP_EQ: "({0}=={1})",
    ca.OP_NE: "({0}!={1})",
    ca.OP_NOT: "(!{t0})",  # !x
    ca.OP_AND: "({t0}&{t1})",  # x&&y (no side effects: no short circuit needed)
    ca.OP_OR: "({t0}|{t1})",  # x||y
}
# Selections are written as bit masks, not ?:, so that gcc does not sink the arithmetic of
# one arm into a branch (which stops if-conversion and vectorisation); the bits are the same.
_LANE_HELPERS = r"""
#include <string.h>
typedef unsigned long long mrpctl_bits_t;
static inline mrpctl_bits_t mrpctl_bits(double x) { mrpctl_bits_t u; memcpy(&u, &x, sizeof u); return u; }
static inline double mrpctl_real(mrpctl_bits_t u) { double x; memcpy(&x, &u, sizeof x); return x; }
/* the mask of a C condition: all ones if true, zero if false */
#define L_MASK(c) (-(mrpctl_bits_t)(c))
/* m ? a : b for a mask m, bit for bit */
#define L_SELECT(m, a, b) mrpctl_real((mrpctl_bits(a) & (m)) | (mrpctl_bits(b) & ~(m)))
/* (double)c of a C condition: 1.0 or +0.0 */
#define L_BOOL(c) mrpctl_real(0x3ff0000000000000ULL & L_MASK(c))
"""
# fmin/fmax: casadi_fmin/casadi_fmax call the C99 fmin/fmax of the libm; the lane form is
# chosen by probing that libm (see _min_max_forms) so that ties of +0/-0 and NaNs agree.
# Operations evaluated by a libm call in every lane (the same function the scalar code calls).
_CALL_OPS: dict[int, str] = {
    ca.OP_EXP: "exp({0})",
    ca.OP_LOG: "log({0})",
    ca.OP_POW: "pow({0},{1})",
    ca.OP_CONSTPOW: "pow({0},{1})",
    ca.OP_SIN: "sin({0})",
    ca.OP_COS: "cos({0})",
    # tan(±0) is ±0, its argument (C99 Annex F): no call for a zero argument, the main path of the sensor's
    # rotation vector to MRP (both branches of an if_else are computed in every lane; tan(0) on that path)
    ca.OP_TAN: "({0} == 0.0 ? {0} : tan({0}))",
    ca.OP_ASIN: "asin({0})",
    ca.OP_ACOS: "acos({0})",
    ca.OP_ATAN: "atan({0})",
    ca.OP_ATAN2: "atan2({0},{1})",
    ca.OP_SINH: "sinh({0})",
    ca.OP_COSH: "cosh({0})",
    ca.OP_TANH: "tanh({0})",
    ca.OP_ASINH: "asinh({0})",
    ca.OP_ACOSH: "acosh({0})",
    ca.OP_ATANH: "atanh({0})",
    ca.OP_FLOOR: "floor({0})",
    ca.OP_CEIL: "ceil({0})",
    ca.OP_FMOD: "fmod({0},{1})",
    ca.OP_ERF: "erf({0})",
    ca.OP_HYPOT: "hypot({0},{1})",
    ca.OP_LOG1P: "log1p({0})",
    ca.OP_EXPM1: "expm1({0})",
}
_CASADI_VERSION: str = getattr(ca, "__version__", "unknown")
_OP_NAMES = {getattr(ca, name): name for name in dir(ca) if name.startswith("OP_")}


def _constant(value: float) -> str:
    if math.isnan(value):
        return "NAN"
    if math.isinf(value):
        return "INFINITY" if value > 0 else "(-INFINITY)"
    return f"({value.hex()})"  # C99 hexadecimal literal: exact


@dataclass(frozen=True)
class _Port:
    name: str
    nnz: int


@dataclass(frozen=True)
class LaneProgram:
    """The emitted C of one SX Function over W lanes.

    Attributes
    ----------
    code : str
        C source defining ``<name>(in0, ..., out0, ...)`` (``static inline``, restrict pointers to
        (nnz, W) structure-of-arrays buffers) and ``<name>_call(arg, res)``. Inline: in a driver's
        horizon loop, which calls it once a sample, the sample is part of the loop (measured 1.06-1.1x on
        the AVX-512 host against a call per sample: the carried state stays in registers from sample to
        sample, no call, no argument set-up).
    name : str
        The C function name.
    width : int
        W, the lanes.
    inputs, outputs : tuple of (str, int)
        Port names and nonzero counts, in the Function's order.
    dropped : tuple of str
        Outputs that are not computed.
    segments : int
        Loops over lanes in the body (1 per instruction without fusion).
    """

    code: str
    name: str
    width: int
    inputs: tuple[tuple[str, int], ...]
    outputs: tuple[tuple[str, int], ...]
    dropped: tuple[str, ...]
    segments: int


# Latencies (cycles, roughly those of a current x86 core's vector unit) for the issue order of `_issue_order`.
_LATENCY: dict[int, int] = {
    ca.OP_ADD: 3, ca.OP_SUB: 3, ca.OP_MUL: 3, ca.OP_SQ: 3, ca.OP_TWICE: 3, ca.OP_INV: 13, ca.OP_DIV: 13,
    ca.OP_SQRT: 20, ca.OP_LT: 3, ca.OP_LE: 3, ca.OP_EQ: 3, ca.OP_NE: 3, ca.OP_CONST: 0, **dict.fromkeys(_CALL_OPS, 20),
}  # fmt: skip


def _selections(
    ops: Sequence[int], source: Sequence[Sequence[int]], segment: Sequence[int]
) -> dict[int, tuple[int, int, int]]:
    """The additions ``(c?a:0) + (!c?b:0)`` (CasADi's SX if_else: two if_else_zero and their sum) of one segment, as
    k -> (c, a, b): emitted as one selection ``(c ? a : b) + 0.``, the same bits (the zero arm adds +0.0 to the chosen
    value), one blend where the two masked arms and their sum were three vector operations."""
    found: dict[int, tuple[int, int, int]] = {}
    for k, op in enumerate(ops):
        if op != ca.OP_ADD or any(ops[o] != ca.OP_IF_ELSE_ZERO or segment[o] != segment[k] for o in source[k]):
            continue
        (c_first, a), (c_second, b) = source[source[k][0]], source[source[k][1]]
        for c, chosen, other, negated in ((c_first, a, b, c_second), (c_second, b, a, c_first)):
            if ops[negated] == ca.OP_NOT and source[negated][0] == c and segment[c] == segment[negated] == segment[k]:
                found[k] = (c, chosen, other)
                break
    return found


# Operations whose result is rounded arithmetic: never a signaling NaN (an IEEE operation quiets it). The libm
# calls are left out: a library may pass a NaN argument through as it is.
_ARITHMETIC = {ca.OP_ADD, ca.OP_SUB, ca.OP_MUL, ca.OP_DIV, ca.OP_SQ, ca.OP_TWICE, ca.OP_INV, ca.OP_SQRT}


def _clean(
    function: ca.Function,
    ops: Sequence[int],
    source: Sequence[Sequence[int]],
    selections: Mapping[int, tuple[int, int, int]],
) -> list[bool]:
    """Per instruction: its value is never -0.0 nor a signaling NaN, whatever the inputs (round to nearest, gradual
    underflow: the default floating-point environment). For such a value x, x + 0.0 is x bit for bit, so a
    selection between two clean values needs no ``+ 0.``. An input may be anything; a sum is -0.0 only if both
    terms are, a difference only if its first term is; x², |x| and 0/1 values never are; products, quotients,
    negations and libm results may be (and |x| of an input may be a signaling NaN)."""
    never_negative_zero = [False] * len(ops)
    quiet = [False] * len(ops)  # never a signaling NaN
    for k, op in enumerate(ops):
        operands = source[k]
        if op == ca.OP_CONST:
            value = float(function.instruction_constant(k))
            never_negative_zero[k] = not (value == 0 and math.copysign(1.0, value) < 0)
            quiet[k] = True  # NaN constants are written as NAN, a quiet NaN
        elif op in _MASK_OPS:
            never_negative_zero[k] = quiet[k] = True
        elif k in selections:
            never_negative_zero[k] = quiet[k] = True  # (c ? a : b) + 0., or the selection of two clean values
        elif op in (ca.OP_ASSIGN, ca.OP_IF_ELSE_ZERO, ca.OP_SIGN, ca.OP_FMIN, ca.OP_FMAX, ca.OP_NEG, ca.OP_FABS):
            chosen = operands[1:] if op == ca.OP_IF_ELSE_ZERO else operands
            quiet[k] = all(quiet[o] for o in chosen)
            if op in (ca.OP_FABS,):
                never_negative_zero[k] = True
            elif op != ca.OP_NEG:
                never_negative_zero[k] = all(never_negative_zero[o] for o in chosen)
        elif op in _ARITHMETIC:
            quiet[k] = True
            if op == ca.OP_ADD:
                never_negative_zero[k] = any(never_negative_zero[o] for o in operands)
            elif op in (ca.OP_SUB, ca.OP_TWICE, ca.OP_SQRT):
                never_negative_zero[k] = never_negative_zero[operands[0]]
            elif op == ca.OP_SQ:
                never_negative_zero[k] = True
    return [a and b for a, b in zip(never_negative_zero, quiet, strict=True)]


def _issue_order(
    ops: Sequence[int],
    source: Sequence[Sequence[int]],
    segment: Sequence[int],
    defs: Sequence[int | None],
    crosses: Sequence[bool],
    selections: Mapping[int, tuple[int, int, int]],
) -> list[float]:
    """A key per instruction: within a segment its instructions are emitted by the earliest cycle at which their
    operands are ready (latency-weighted depth, `_LATENCY`; ties in CasADi's order), so that a long dependency
    chain (the integrator's) and the work beside it (the statistics) come interleaved and an out-of-order core
    finds the independent work within its window; the values are the same (the same operations on the same
    operands). A value read from an earlier segment's array comes before the write of its slot in this one."""
    issue = [0.0] * len(ops)
    ready = [0.0] * len(ops)
    read_at: dict[tuple[int, int | None], float] = {}  # (segment, slot): the latest reader of the slot's old value
    for k, op in enumerate(ops):
        start = max((ready[origin] for origin in source[k] if segment[origin] == segment[k]), default=0.0)
        if crosses[k]:
            start = max(start, read_at.get((segment[k], defs[k]), 0.0))
        for origin in source[k]:
            if segment[origin] != segment[k]:
                read_at[segment[k], defs[origin]] = max(read_at.get((segment[k], defs[origin]), 0.0), start)
        issue[k] = start + k * 1e-6  # ties in CasADi's order
        ready[k] = start + (4 if k in selections else _LATENCY.get(op, 1))
    return issue


def emit_lanes(
    function: ca.Function,
    width: int,
    *,
    name: str = "mrpctl_lanes",
    fuse: bool = True,
    drop: Sequence[str] = (),
    ivdep: bool = False,
    standalone: bool = False,
    shared: Sequence[str] = (),
) -> LaneProgram:
    """Emit C evaluating a pure SX Function on ``width`` lanes at once.

    Parameters
    ----------
    function : casadi.Function
        A pure SX Function (no calls to other Functions, no free variables).
    width : int
        W >= 1, the lanes (a compile-time constant of the code).
    name : str, keyword-only
        Name of the emitted C function.
    fuse : bool, keyword-only
        One loop over lanes per run of vectorisable instructions (True) or per instruction.
    drop : sequence of str, keyword-only
        Output names not to compute.
    ivdep : bool, keyword-only
        Put ``#pragma GCC ivdep`` before every lane loop.
    shared : sequence of str, keyword-only
        Input names whose values are the same in every lane: read from a (nnz,) buffer, not
        (nnz, W) (e.g. a per-sample noise stream shared by the runs of a batch).
    standalone : bool, keyword-only
        Also export ``<name>_eval(const double** arg, double** res)`` (for tests).

    Returns
    -------
    LaneProgram

    Raises
    ------
    CodegenError
        If the Function is not SX or uses an operation without a bit-identical lane form.
    """
    width = integer("width", width, minimum=1)
    if not function.is_a("SXFunction"):
        raise CodegenError(f"emit_lanes needs a pure SX Function, got {function.class_name()} {function.name()!r}")
    if function.has_free():
        raise CodegenError(f"{function.name()}: free variables {function.get_free()} cannot be emitted")
    inputs = tuple(_Port(function.name_in(i), function.nnz_in(i)) for i in range(function.n_in()))
    outputs = tuple(_Port(function.name_out(i), function.nnz_out(i)) for i in range(function.n_out()))
    dropped = tuple(drop)
    unknown = sorted(set(dropped) - {port.name for port in outputs})
    if unknown:
        raise SpecificationError(f"drop: {unknown} are not outputs of {function.name()} ({[p.name for p in outputs]})")
    dropped_index = {i for i, port in enumerate(outputs) if port.name in dropped}
    unknown_shared = sorted(set(shared) - {port.name for port in inputs})
    if unknown_shared:
        raise SpecificationError(f"shared: {unknown_shared} are not inputs of {function.name()}")
    shared_index = {i for i, port in enumerate(inputs) if port.name in shared}
    vector_ops = dict(_VECTOR_OPS)
    vector_ops.update(min_max_forms())
    vector_ops.update(_MASK_OPS)

    # Decode the instruction list: (op, output slot or None, input slots, text template).
    count = function.n_instructions()
    ops: list[int] = []
    defs: list[int | None] = []
    reads: list[list[int]] = []
    for k in range(count):
        op = function.instruction_id(k)
        ops.append(op)
        if op == ca.OP_INPUT:
            defs.append(function.instruction_output(k)[0])
            reads.append([])
        elif op == ca.OP_OUTPUT:
            defs.append(None)
            keep = function.instruction_output(k)[0] not in dropped_index
            reads.append([function.instruction_input(k)[0]] if keep else [])
        elif op == ca.OP_CONST:
            defs.append(function.instruction_output(k)[0])
            reads.append([])
        elif op in vector_ops or op in _CALL_OPS:
            defs.append(function.instruction_output(k)[0])
            template = vector_ops.get(op) or _CALL_OPS[op]
            arity = 2 if "{1}" in template or "{t1}" in template else 1
            reads.append(list(function.instruction_input(k)[:arity]))
        else:
            label = _OP_NAMES.get(op, str(op))
            if op in (ca.OP_FMIN, ca.OP_FMAX):
                reason = "this host's libm fmin/fmax match no known lane form"
            else:
                reason = "no bit-identical lane form"
            raise CodegenError(
                f"{function.name()}: cannot vectorise instruction {k} ({label}): {reason}; supported: "
                + ", ".join(sorted(_OP_NAMES[o] for o in (*vector_ops, *_CALL_OPS) if o in _OP_NAMES))
            )

    # Segments: maximal runs of vectorisable instructions (fuse) or one per instruction.
    segment = [0] * count
    current = 0
    for k in range(count):
        call = ops[k] in _CALL_OPS
        if k > 0 and (not fuse or call or ops[k - 1] in _CALL_OPS):
            current += 1
        segment[k] = current

    # Which definition each read refers to; values read in another segment go through arrays.
    last_def: dict[int, int] = {}
    source: list[list[int]] = []
    crosses = [False] * count
    for k in range(count):
        refs = []
        for slot in reads[k]:
            if slot not in last_def:
                raise CodegenError(f"{function.name()}: instruction {k} reads work variable {slot} before writing it")
            origin = last_def[slot]
            refs.append(origin)
            if segment[origin] != segment[k]:
                crosses[origin] = True
        source.append(refs)
        defined = defs[k]
        if defined is not None:
            last_def[defined] = k
    array_slots = sorted({slot for k, slot in enumerate(defs) if crosses[k] and slot is not None})
    selections = _selections(ops, source, segment)
    clean = _clean(function, ops, source, selections)
    issue = _issue_order(ops, source, segment, defs, crosses, selections)

    def value(origin: int, at: int) -> str:
        if segment[origin] == segment[at]:
            return f"v{origin}"
        return f"w{defs[origin]}[l]"

    def local(*origins: int, at: int) -> bool:
        return all(segment[origin] == segment[at] for origin in origins)

    def truth(origin: int, at: int) -> str:
        if local(origin, at=at) and ops[origin] in _MASK_OPS:
            return f"m{origin}"
        if local(origin, at=at) and ops[origin] == ca.OP_IF_ELSE_ZERO:
            condition, chosen = source[origin]
            if local(condition, at=at) and ops[chosen] == ca.OP_CONST and function.instruction_constant(chosen) != 0:
                return truth(condition, at)  # (c ? k : 0) != 0 is c for a constant k != 0 (NaN included)
        return f"({value(origin, at)}!=0.)"

    def selection(at: int) -> str:
        c, chosen, other = selections[at]
        text = f"L_SELECT(L_MASK({truth(c, at)}), {value(chosen, at)}, {value(other, at)})"
        return text if clean[chosen] and clean[other] else f"({text}+0.)"

    lines: list[str] = []
    pragma = "    #pragma GCC ivdep\n" if ivdep else ""
    k = 0
    segments = 0
    while k < count:
        start = k
        while k < count and segment[k] == segment[start]:
            k += 1
        body: list[str] = []
        for j in sorted(range(start, k), key=issue.__getitem__):
            op = ops[j]
            if op == ca.OP_INPUT:
                port, nz = function.instruction_input(j)
                text = f"i{port}[{nz}]" if port in shared_index else f"i{port}[{nz * width}+l]"
            elif op == ca.OP_CONST:
                text = _constant(float(function.instruction_constant(j)))
            elif op == ca.OP_OUTPUT:
                port, nz = function.instruction_output(j)
                if port not in dropped_index:
                    body.append(f"o{port}[{nz * width}+l] = {value(source[j][0], j)};")
                continue
            elif j in selections:
                text = selection(j)
            else:
                template = vector_ops.get(op) or _CALL_OPS[op]
                operands = source[j]
                masks = {f"t{i}": truth(origin, j) for i, origin in enumerate(operands) if f"{{t{i}}}" in template}
                text = template.format(*(value(origin, j) for origin in operands), **masks)
                if op in _MASK_OPS:
                    body.append(f"const int m{j} = {text};")
                    text = f"L_BOOL(m{j})"
            body.append(f"const double v{j} = {text};")
            if crosses[j]:
                body.append(f"w{defs[j]}[l] = v{j};")
        if body:
            segments += 1
            lines.append(pragma + "    for (l = 0; l < W; ++l) {\n      " + "\n      ".join(body) + "\n    }")

    in_params = [f"const double* restrict i{i}" for i in range(len(inputs))]
    out_params = [f"double* restrict o{i}" for i in range(len(outputs))]
    declarations = "".join(f"  double w{slot}[W] __attribute__((aligned(64)));\n" for slot in array_slots)
    call_args = [f"arg[{i}]" for i in range(len(inputs))] + [f"res[{i}]" for i in range(len(outputs))]
    signature = ", ".join(in_params + out_params) or "void"
    code = (
        f"/* {name}: {function.name()} on W = {width} lanes, emitted by mrpctl.engines.lanes from "
        f"{count} CasADi {_CASADI_VERSION} instructions */\n"
        "#include <math.h>\n" + _LANE_HELPERS + f"#undef W\n#define W {width}\n"
        f"static inline void {name}({signature}) {{\n"
        "  int l;\n" + declarations + "\n".join(lines) + "\n}\n"
        f"static inline void {name}_call(const double** arg, double** res) {{\n"
        f"  {name}({', '.join(call_args)});\n}}\n#undef W\n"
    )
    if standalone:
        code += (
            f'__attribute__((visibility("default"))) int {name}_eval(const double** arg, double** res) {{\n'
            f"  {name}_call(arg, res);\n  return 0;\n}}\n"
        )
    return LaneProgram(
        code=code,
        name=name,
        width=width,
        inputs=tuple((port.name, port.nnz) for port in inputs),
        outputs=tuple((port.name, port.nnz) for port in outputs),
        dropped=dropped,
        segments=segments,
    )


# ------------------------------------------------------------------ flags and the build
