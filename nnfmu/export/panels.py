"""Fast profile: constant weight matrices stored as row panels, and the C rewrites that use them.

A matrix-vector product streams every weight once per step, so its speed is
set by how the weights come through the cache. CasADi stores a constant
matrix column-major; a vectorised product over blocks of rows then jumps by a
whole column between consecutive loads, which the hardware prefetchers follow
poorly once the matrix outgrows the L2 cache. :func:`panelize` rewrites every
constant that is used *only* as the left factor of ``casadi_mtimes_dense``
(weights of ``mtimes(W, v)``) into row panels (see ``csrc/nnfmu_fast.h``):
blocks of up to 32 rows (64 in float32), each stored column after column, so that the
kernel reads the weights strictly in order and keeps one block's sums in
registers. Values are moved as CasADi printed them (the text is permuted, not
re-parsed), so the matrix is the same bits; a constant used anywhere else is
left alone, and its products use the generic kernel.

:func:`use_fast_math` points the element-wise ``exp``, ``tanh``, ``fmax`` and
``fmin`` of the model functions at the branch-free versions in the same file.
"""

from __future__ import annotations

import re

#: rows per 32-byte vector of the kernel (csrc/nnfmu_fast.h); a panel block holds up to 8 vectors
VECTOR_ROWS = {"float64": 4, "float32": 8}

_CONSTANT = re.compile(r"^static const casadi_real (casadi_c\d+)\[(\d+)\] = ?\s*\{(.*?)\};\n", re.S | re.M)
_FUNCTION = re.compile(r"^static int casadi_f\d+\(.*?^}\n", re.S | re.M)
_BIND = re.compile(r"^\s*(\w+) = (casadi_c\d+);$")
_ASSIGN = re.compile(r"^\s*(\w+) = ")
_MTIMES = re.compile(r"casadi_mtimes_dense\((\w+), (\d+), (\d+), ([^,]+), (\d+), ([^,]+), ([01])\);")
_IDENT = re.compile(r"\b[A-Za-z_]\w*\b")
_MATH = {r"\bexp\(": "nnfmu_exp(", r"\btanh\(": "nnfmu_tanh(",
         r"\bcasadi_fmax\(": "nnfmu_fmax(", r"\bcasadi_fmin\(": "nnfmu_fmin("}


def panel_heights(nrow: int, vector: int) -> list[int]:
    """Heights of the blocks of a matrix with ``nrow`` rows: full blocks of 8 ``vector`` rows, then the
    rest rounded up to a multiple of ``vector`` (mirrors ``nnfmu_gemv_panel``)."""
    heights = [8 * vector] * (nrow // (8 * vector))
    rest = nrow - 8 * vector * len(heights)
    if rest:
        heights.append(-(-rest // vector) * vector)
    return heights


def panel_order(values: list[str], nrow: int, ncol: int, vector: int) -> list[str]:
    """Column-major ``values`` of an ``nrow x ncol`` matrix in panel order, zero-padded (see the module doc)."""
    out, first = [], 0
    for height in panel_heights(nrow, vector):
        for k in range(ncol):
            column = values[k * nrow + first:k * nrow + min(first + height, nrow)]
            out += column + ["0."] * (height - len(column))
        first += height
    return out


def _scan(source: str) -> tuple[dict, set]:
    """Shapes of the constants used as the left factor of ``casadi_mtimes_dense`` (with tr = 0), and the
    constants used in any other way (read, offset, passed on, transposed)."""
    shapes: dict[str, set] = {}
    other: set[str] = set()
    for body in _FUNCTION.findall(source):
        bound: dict[str, str] = {}
        for line in body.splitlines()[1:]:
            bind = _BIND.match(line)
            if bind:
                bound[bind.group(1)] = bind.group(2)
                continue
            call = _MTIMES.search(line)
            names = _IDENT.findall(line)
            if call:
                x = call.group(1)
                constant = bound.get(x, x if x.startswith("casadi_c") else None)
                if constant is not None:
                    shapes.setdefault(constant, set()).add((int(call.group(2)), int(call.group(3)), call.group(7)))
                names = _IDENT.findall(line[call.end(1):])
            other |= {bound.get(n, n) for n in names if n in bound or re.fullmatch(r"casadi_c\d+", n)}
            assign = _ASSIGN.match(line)
            if assign and not call:
                bound.pop(assign.group(1), None)
    return shapes, other


def panelize(source: str, precision: str) -> str:
    """Store the weight constants of ``source`` as row panels and call ``nnfmu_gemv_panel`` on them."""
    vector = VECTOR_ROWS[precision]
    shapes, other = _scan(source)
    sizes = {m.group(1): int(m.group(2)) for m in _CONSTANT.finditer(source)}
    panels = {c: next(iter(s))[:2] for c, s in shapes.items()
              if c not in other and len(s) == 1 and next(iter(s))[2] == "0"
              and next(iter(s))[0] * next(iter(s))[1] == sizes.get(c)}
    if not panels:
        return source

    def constant(match: re.Match) -> str:
        name = match.group(1)
        if name not in panels:
            return match.group(0)
        values = [v.strip() for v in match.group(3).split(",")]
        ordered = panel_order(values, *panels[name], vector)
        lines = ",\n  ".join(", ".join(ordered[i:i + 8]) for i in range(0, len(ordered), 8))
        return f"static const casadi_real {name}[{len(ordered)}] = {{\n  {lines}}};\n"

    def function(match: re.Match) -> str:
        bound: dict[str, str] = {}
        lines = []
        for line in match.group(0).splitlines(keepends=True):
            bind, assign, call = _BIND.match(line.rstrip("\n")), _ASSIGN.match(line), _MTIMES.search(line)
            if bind:
                bound[bind.group(1)] = bind.group(2)
            elif assign:
                bound.pop(assign.group(1), None)
            if call and bound.get(call.group(1), call.group(1)) in panels:
                x, nrow, ncol, y, ncol_y, z, _ = call.groups()
                line = line.replace(call.group(0), f"nnfmu_gemv_panel({x}, {nrow}, {ncol}, {y}, {ncol_y}, {z});")
            lines.append(line)
        return "".join(lines)

    return _FUNCTION.sub(function, _CONSTANT.sub(constant, source))


def use_fast_math(source: str) -> str:
    """Element-wise exp, tanh, fmax and fmin of the model functions -> the vectorisable nnfmu versions."""
    def function(match: re.Match) -> str:
        body = match.group(0)
        for pattern, replacement in _MATH.items():
            body = re.sub(pattern, replacement, body)
        return body

    return _FUNCTION.sub(function, source)
