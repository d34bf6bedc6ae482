"""A mechanism's numbers as inputs of its compiled functions: one C library per structure.

A CasADi SX function holds its numbers (masses, lengths, stiffnesses, stop positions,
gravity, tolerances, but also the 2 of a square) as constants of its algorithm, so
generated C holds them too, and every parameter variant (a sweep's case, a design step, a
finite difference) built and cached a library of its own: 1.2 s for a variant of the
double-folded mechanism against 0.02 s for its warm run. :func:`lift` rebuilds such a
function with each constant of its algorithm read from an input instead, in the order the
algorithm meets them, and returns the constants' values beside it. The lifted function
does the same operations in the same order on the same numbers (a constant is loaded,
not folded: the results are the same to the last bit); two mechanisms that differ only
in their numbers have the same lifted functions, hence the same library key
(:func:`~.codegen.function_key`), and share one build.

A number the model's builder folded into its structure (a zero that removed a term, two
equal constants CasADi keeps as one node) gives another structure: its own build, as
before, never a wrong one (the key is the lifted function itself).
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from dataclasses import dataclass

import casadi as ca
import numpy as np
from casadi import _casadi as _swig

__all__ = ["Lifted", "external", "lift", "wrap"]


@dataclass(frozen=True)
class Lifted:
    """A function with its constants as inputs.

    Attributes
    ----------
    fn : casadi.Function
        The lifted function: the original's inputs, input ``into`` extended (or appended)
        to ``offset + len(values)`` entries, the original input's in front and the
        constants at ``offset`` onwards.
    values : numpy.ndarray
        The original function's constants, in the order ``fn`` reads them.
    """

    fn: ca.Function
    values: np.ndarray


#: Lifted functions by the structure of their originals (their algorithm but for the
#: constants' values, their inputs' and outputs' patterns, where the constants go): the
#: variants of one mechanism read their constants, they are not rebuilt (a sweep's case
#: of the double-folded mechanism: 4 ms instead of 40). Bounded, the oldest first out.
_SHAPES: OrderedDict[bytes, tuple[ca.Function, list[int]]] = OrderedDict()
_SHAPES_LOCK = threading.Lock()  # (a background build lifts too)
SHAPES_KEPT = 64


def lift(f: ca.Function, into: int | None = None, offset: int | None = None) -> Lifted:
    """``f`` (an SX function) with the constants of its algorithm read from one input.

    Parameters
    ----------
    f : casadi.Function
        An SXFunction (MX functions raise TypeError: compose them of lifted SX functions).
    into : int or None
        The input (a column vector) the constants are appended to, e.g. a configuration's
        parameters ``p``; None appends a new input ``w`` holding them alone.
    offset : int or None
        Where in that input the constants start (at least its own length; default just
        after it): several lifted functions read their constants from one shared vector.

    Returns
    -------
    Lifted
    """
    if not f.is_a("SXFunction"):
        raise TypeError(f"{f.name()}: only SX functions are lifted ({f.class_name()})")
    if into is not None and f.size2_in(into) != 1:
        raise ValueError(f"{f.name()}: input {into} is not a column vector")
    base = 0 if into is None else f.nnz_in(into)
    offset = base if offset is None else offset
    if offset < base:
        raise ValueError(f"{f.name()}: offset {offset} overlaps input {into} ({base})")
    n = f.n_instructions()
    # (CasADi's own calls, not its Python wrappers: a third of the time)
    ids = [_swig.Function_instruction_id(f, k) for k in range(n)]
    ins = [_swig.Function_instruction_input(f, k) for k in range(n)]
    outs = [_swig.Function_instruction_output(f, k) for k in range(n)]
    shape = hashlib.sha256(repr((
        f.name(), f.name_in(), f.name_out(), into, offset,
        [f.sparsity_in(i).serialize() for i in range(f.n_in())],
        [f.sparsity_out(i).serialize() for i in range(f.n_out())], ids, ins, outs)
    ).encode()).digest()
    with _SHAPES_LOCK:
        got = _SHAPES.get(shape)
        if got is not None:
            _SHAPES.move_to_end(shape)
    if got is None:
        got = _rebuild(f, ids, ins, outs, into, offset)
        with _SHAPES_LOCK:
            _SHAPES[shape] = got
            while len(_SHAPES) > SHAPES_KEPT:
                _SHAPES.popitem(last=False)
    g, consts = got
    return Lifted(g, np.array([_swig.Function_instruction_constant(f, k) for k in consts],
                              dtype=float))


def _rebuild(f: ca.Function, ids: list[int], ins: list, outs: list, into: int | None,
             offset: int) -> tuple[ca.Function, list[int]]:
    """The lifted function, rebuilt instruction by instruction; the instructions that
    were constants, in the order it reads them."""
    consts = [k for k, op in enumerate(ids) if op == ca.OP_CONST]
    xs = f.sx_in()
    names = list(f.name_in())
    pw = ca.SX.sym(names[into] if into is not None else "w", offset + len(consts))
    new_ins, args = list(xs), [x.nz for x in xs]
    if into is None:
        new_ins.append(pw)
        names.append("w")
    else:  # the original entries are the front of the extended input
        new_ins[into], args[into] = pw, pw.nz
    work: dict[int, ca.SX] = {}
    res = [[ca.SX(0)] * f.nnz_out(i) for i in range(f.n_out())]
    c = offset
    op_const, op_input, op_output = ca.OP_CONST, ca.OP_INPUT, ca.OP_OUTPUT
    unary, binary = ca.SX.unary, ca.SX.binary
    for op, i, o in zip(ids, ins, outs, strict=True):
        if op == op_const:
            work[o[0]] = pw[c]
            c += 1
        elif op == op_input:
            work[o[0]] = args[i[0]][i[1]]
        elif op == op_output:
            res[o[0]][o[1]] = work[i[0]]
        elif len(i) == 1:
            work[o[0]] = unary(op, work[i[0]])
        else:
            work[o[0]] = binary(op, work[i[0]], work[i[1]])
    outs_sx = [ca.SX(f.sparsity_out(j), ca.vertcat(*res[j])) if res[j]
               else ca.SX(f.sparsity_out(j)) for j in range(f.n_out())]
    return ca.Function(f.name(), new_ins, outs_sx, names, list(f.name_out())), consts


_EXTERNALS: dict[tuple[str, str], ca.Function] = {}


def external(name: str, lib: str) -> ca.Function:
    """The compiled function ``name`` of the library ``lib``, loaded once per process: a
    lifted function has no numbers of its own, so every variant of a mechanism uses the
    same one."""
    key = (name, lib)
    fn = _EXTERNALS.get(key)
    if fn is None:
        fn = _EXTERNALS[key] = ca.external(name, lib)
    return fn


def wrap(ext: ca.Function, values: np.ndarray) -> ca.Function:
    """A lifted function's compiled version (``ext``, its constants a last input ``w``)
    as a function of the original inputs again, the constants ``values`` bound: what
    the model's own function was, for every caller (a call, a map, a buffer)."""
    ins = [ca.MX.sym(ext.name_in(i), ext.sparsity_in(i)) for i in range(ext.n_in() - 1)]
    outs = ext.call([*ins, ca.DM(values)])
    return ca.Function(ext.name(), ins, outs, ext.name_in()[:-1], ext.name_out())
