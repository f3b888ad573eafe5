"""CasADi SX functions as plain data: the table of their algorithm, replayed with known operations only.

A grey-box model is its CasADi functions; an archive that holds such a model must hold them. CasADi's own
serialisation can name external code (a compiled library that deserialising would load), which an
archive must never run, and its text is opaque to the archive's tools. :func:`function_table` therefore
writes an SX function as arrays: the sparsity of each input and output and one row per instruction of
its algorithm (the operation's code, where its result goes, what it reads, a constant). :func:`table_function`
rebuilds the function by replaying the rows with scalar arithmetic alone: an operation outside
:data:`SCALAR_OPERATIONS` (a call of another function, a free parameter, a print) is refused. The rebuilt
function performs the same operations in the same order, so it evaluates to the same bits.
"""

from __future__ import annotations

from typing import Any, Mapping

import casadi as ca
import numpy as np

from .errors import ArchiveError, InputError

__all__ = ["SCALAR_OPERATIONS", "function_table", "table_function"]

#: The operation codes a stored function may use: elementwise arithmetic, comparisons and the usual functions.
SCALAR_OPERATIONS = frozenset(getattr(ca, f"OP_{name}") for name in (
    "ASSIGN", "ADD", "SUB", "MUL", "DIV", "NEG", "EXP", "LOG", "POW", "CONSTPOW", "SQRT", "SQ", "TWICE", "SIN",
    "COS", "TAN", "ASIN", "ACOS", "ATAN", "LT", "LE", "EQ", "NE", "NOT", "AND", "OR", "FLOOR", "CEIL", "FMOD",
    "FABS", "SIGN", "COPYSIGN", "IF_ELSE_ZERO", "ERF", "FMIN", "FMAX", "INV", "SINH", "COSH", "TANH", "ASINH",
    "ACOSH", "ATANH", "ATAN2", "ERFINV", "LOG1P", "EXPM1", "HYPOT", "REMAINDER"))
_MOVES = (ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_CONST)


def _sparsity_rows(sparsities: list[ca.Sparsity]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shapes (k, 2), and the column pointers and row indices of every pattern, concatenated with their offsets."""
    shapes = np.array([[s.size1(), s.size2()] for s in sparsities], dtype=np.int64).reshape(-1, 2)
    columns = [np.asarray(s.colind(), dtype=np.int64) for s in sparsities]
    rows = [np.asarray(s.row(), dtype=np.int64) for s in sparsities]
    return shapes, np.concatenate(columns or [np.zeros(0, np.int64)]), np.concatenate(rows or [np.zeros(0, np.int64)])


def function_table(function: ca.Function) -> dict[str, Any]:
    """An SX function as plain arrays and names (module docstring).

    Parameters
    ----------
    function : casadi.Function
        An SX function, or an MX function that expands to one.

    Returns
    -------
    dict
        ``name``, ``input_names``, ``output_names``, ``symbols`` (the inputs' nonzeros' names) (str);
        ``input_shapes``, ``output_shapes`` (k, 2);
        ``input_colind``, ``input_row``, ``output_colind``, ``output_row`` (the patterns, concatenated);
        ``operations`` (n, 4) int: code, target, first and second operand (-1 where unused); ``constants`` (n,).

    Raises
    ------
    InputError
        For a function that uses an operation outside :data:`SCALAR_OPERATIONS`.
    """
    if function.is_a("MXFunction"):
        function = function.expand()
    if not function.is_a("SXFunction"):
        raise InputError(f"only SX functions can be stored; {function.name()} is a {function.class_name()}")
    operations = np.full((function.n_instructions(), 4), -1, dtype=np.int64)
    constants = np.zeros(function.n_instructions())
    for k in range(function.n_instructions()):
        code = int(function.instruction_id(k))
        if code not in SCALAR_OPERATIONS and code not in _MOVES:
            raise InputError(f"{function.name()} uses CasADi operation {code}, which a stored function may not")
        operands = [int(v) for v in function.instruction_input(k)]
        targets = [int(v) for v in function.instruction_output(k)]
        # the target first: a work slot, or (output, nonzero); then the operands: (input, nonzero) or work slots
        row = [*targets, *operands]
        if code == ca.OP_CONST:
            constants[k] = function.instruction_constant(k)
        operations[k, 0] = code
        operations[k, 1:1 + len(row)] = row
    inputs = _sparsity_rows([function.sparsity_in(i) for i in range(function.n_in())])
    outputs = _sparsity_rows([function.sparsity_out(i) for i in range(function.n_out())])
    # the symbols' own names, nonzero by nonzero: they are part of the function (and of its compiled code's key)
    symbols = tuple(function.sx_in(i).nz[k].name() for i in range(function.n_in()) for k in range(function.nnz_in(i)))
    return {
        "name": function.name(), "input_names": tuple(function.name_in()), "output_names": tuple(function.name_out()),
        "symbols": symbols,
        "input_shapes": inputs[0], "input_colind": inputs[1], "input_row": inputs[2],
        "output_shapes": outputs[0], "output_colind": outputs[1], "output_row": outputs[2],
        "operations": operations, "constants": constants,
    }


def _patterns(shapes: Any, colind: Any, row: Any, what: str) -> list[ca.Sparsity]:
    """The sparsity patterns written by :func:`_sparsity_rows`."""
    shapes, colind, row = (np.asarray(v, dtype=np.int64) for v in (shapes, colind, row))
    patterns, column_at, row_at = [], 0, 0
    for rows, columns in shapes.reshape(-1, 2):
        pointers = colind[column_at:column_at + columns + 1]
        count = int(pointers[-1]) if pointers.size else 0
        patterns.append(ca.Sparsity(int(rows), int(columns), pointers.tolist(), row[row_at:row_at + count].tolist()))
        column_at, row_at = column_at + columns + 1, row_at + count
    if column_at != colind.size or row_at != row.size:
        raise ArchiveError(f"the stored {what} patterns do not add up")
    return patterns


def table_function(table: Mapping[str, Any]) -> ca.Function:
    """The SX function that :func:`function_table` wrote, rebuilt by replaying its operations.

    Parameters
    ----------
    table : mapping
        As :func:`function_table` returns it (arrays may come back as lists or tuples).

    Returns
    -------
    casadi.Function

    Raises
    ------
    ArchiveError
        For an operation outside :data:`SCALAR_OPERATIONS`, or a table that does not describe a function.

    Examples
    --------
    >>> import casadi as ca
    >>> x = ca.SX.sym("x", 2)
    >>> f = ca.Function("f", [x], [ca.tanh(x[0]) * 3.0 + x[1] ** 2], ["x"], ["y"])
    >>> g = table_function(function_table(f))
    >>> float(g([0.4, -1.5])) == float(f([0.4, -1.5]))
    True
    """
    try:
        inputs = _patterns(table["input_shapes"], table["input_colind"], table["input_row"], "input")
        outputs = _patterns(table["output_shapes"], table["output_colind"], table["output_row"], "output")
        operations = np.asarray(table["operations"], dtype=np.int64).reshape(-1, 4)
        constants = np.asarray(table["constants"], dtype=float).ravel()
        input_names, output_names = list(table["input_names"]), list(table["output_names"])
        names = iter(table["symbols"])
        symbols = [ca.SX(pattern) for pattern in inputs]
        for symbol in symbols:
            for k in range(symbol.nnz()):
                symbol.nz[k] = ca.SX.sym(str(next(names)))
        results = [ca.SX(pattern) for pattern in outputs]
        work: dict[int, Any] = {}
        for (code, a, b, c), constant in zip(operations.tolist(), constants.tolist()):
            if code == ca.OP_INPUT:
                work[a] = symbols[b].nz[c]
            elif code == ca.OP_OUTPUT:
                results[a].nz[b] = work[c]
            elif code == ca.OP_CONST:
                work[a] = ca.SX(constant)
            elif code in SCALAR_OPERATIONS:
                work[a] = ca.SX.unary(code, work[b]) if c < 0 else ca.SX.binary(code, work[b], work[c])
            else:
                raise ArchiveError(f"a stored function uses CasADi operation {code}, which is not read")
        return ca.Function(str(table["name"]), symbols, results, input_names, output_names)
    except (KeyError, IndexError, TypeError, ValueError, RuntimeError) as exc:
        raise ArchiveError(f"the stored function cannot be rebuilt: {exc}") from None
