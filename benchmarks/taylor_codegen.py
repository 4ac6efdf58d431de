r"""What XLA's CPU code makes of the Taylor batch loop: an instruction census.

It compiles the batch-native loop (`lagjax.taylor.batch`) of the double pendulum
for one tile of members, has XLA dump its object code (`--xla_dump_to`), and
counts in `objdump -dr`'s disassembly of the loop's kernel:

- the floating-point arithmetic by width: packed on 256-bit `ymm` registers (4
  doubles), packed on `xmm` (2), or scalar (`…sd`), fused multiply-adds apart;
- the calls out of the kernel by symbol (libm's `sin`, `cos`, `pow`, libc's
  `memset`, `memcpy`): scalar work that XLA's vectorizer never sees;
- the innermost loops that hold packed multiply-adds (the tape's inner Cauchy
  sums, one loop per order) and their widths.

The counts are static (instructions in the code, not executed ones). What it
showed (jax 0.10.2, AMD EPYC with AVX2 + FMA, tol 1e-12, order 15,
2026-11-28), with `perf` for where the time goes:

- tile of 32: multiply-adds 523 on `ymm`, 32 scalar; multiplications 274 /
  160, subtractions 211 / 128. The 14 innermost loops with multiply-adds (the
  inner sums, one per order) hold 187 on `ymm` and none scalar: the sums are
  vectorized, two chains of 4 doubles per iteration. They run at 5.3 Gmadd/s
  against 10 Gmadd/s for a tile of 8 (a loop of the sums alone, core 1): the
  tape of 32 members (155 kB) is read from L2 at every order, that of 8 (38 kB)
  nearly stays in the 32 kB L1 cache;
- tile of 8: multiply-adds 235 on `ymm`, 331 scalar: XLA's loops over 8
  members compile mostly to scalar code, so small tiles lose what their sums
  gain (tiles of 8: 1.2× the time of tiles of 32);
- the scalar work XLA's vectorizer never sees: call sites of libm's `sin`
  (172) and `cos` (228) — XLA unrolls a sine of 32 members into 32 calls — and
  `pow` (the step size): in `perf`, 16 % of the run in `sin`/`cos`, 3.5 % in `pow`;
  a `memset` of the whole tape per step (7 %) until the loop carried its tape;
  the rates read back from the tape by a dynamic slice, scalar (8 % of the
  kernel); per order, the row of new coefficients is assembled by a
  concatenate (XLA's CPU backend fuses none) and then copied into the tape:
  two copies of the row, 17 % of the kernel's time.

Run from the repository root: `python -m benchmarks.taylor_codegen [--tile 32]`
(needs `objdump`, from binutils).

References: the XLA flags `--xla_dump_to` and `--xla_dump_hlo_as_text`; Intel's
and AMD's optimization manuals for the instruction names.
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import jax
import jax.numpy as jnp

from lagjax._core.cpu_loops import enable_fast_cpu_loops
from lagjax.taylor.batch import taylor_integrate_batch

from .taylor import vector_field

ARITHMETIC = re.compile(r"^v?(f?n?m?(?:add|sub)\d*|mul|div|sqrt|add|sub)(p|s)d$")
LINE = re.compile(r"^\s+([0-9a-f]+):\s+(\S+)\s*(.*)$")
CALLED = re.compile(r"R_X86_64_\w+\s+(\w+)")


def kind(opcode: str, operands: str) -> str | None:
    """'fma ymm', 'mul xmm', 'add scalar', … for floating-point arithmetic."""
    match = ARITHMETIC.match(opcode)
    if match is None:
        return None
    fused = opcode.startswith(("vfmadd", "vfmsub", "vfnmadd", "vfnmsub"))
    name = "fma" if fused else opcode.lstrip("v")[:3]
    if match.group(2) == "s":
        return f"{name} scalar"
    return f"{name} {'ymm' if 'ymm' in operands else 'xmm'}"


def disassembly(objects: list[Path]) -> tuple[list[tuple[int, str, str]], list[str]]:
    """(address, opcode, operands) of the largest object's code, and the symbols
    its relocations call (libm, libc)."""
    largest = max(objects, key=lambda path: path.stat().st_size)
    text = subprocess.run(
        ["objdump", "-dr", "--no-show-raw-insn", str(largest)],
        capture_output=True, text=True, check=True,
    ).stdout  # fmt: skip
    instructions, called = [], []
    for line in text.splitlines():
        if match := CALLED.search(line):  # a relocation line, not an instruction
            called.append(match[1])
        elif match := LINE.match(line):
            instructions.append((int(match[1], 16), match[2], match[3]))
    return instructions, called


def innermost_loops(instructions: list) -> list[tuple[int, int]]:
    """(first, last) instruction indices of each loop no other loop is inside,
    from the backward jumps."""
    index = {address: i for i, (address, _, _) in enumerate(instructions)}
    loops = []
    for i, (address, opcode, operands) in enumerate(instructions):
        target = re.match(r"([0-9a-f]+)", operands) if opcode.startswith("j") else None
        if target and int(target[1], 16) <= address and int(target[1], 16) in index:
            loops.append((index[int(target[1], 16)], i))
    return [
        (s, e)
        for s, e in loops
        if not any(s <= s2 and e2 <= e and (s2, e2) != (s, e) for s2, e2 in loops)
    ]


def census(instructions: list) -> collections.Counter:
    return collections.Counter(
        k for _, opcode, operands in instructions if (k := kind(opcode, operands))
    )


def compile_one_tile(tile: int, tol: float) -> int:
    """Compile and run the batch loop for `tile` members; returns its order."""
    y0s = jnp.stack(
        [jnp.linspace(0.1, 1.0, tile), jnp.full(tile, 0.3), jnp.zeros(tile), jnp.zeros(tile)],
        axis=1,
    )  # fmt: skip
    run = jax.jit(
        lambda y: taylor_integrate_batch(
            vector_field, y, 0.0, 1.0, rtol=tol, atol=tol, tile=tile
        )
    )
    return jax.block_until_ready(run(y0s)).order


def main() -> None:
    parser = argparse.ArgumentParser(
        description="An instruction census of the Taylor batch loop"
    )
    parser.add_argument("--tile", type=int, default=32, help="members per tile")
    parser.add_argument("--tol", type=float, default=1e-12)
    options = parser.parse_args()
    if shutil.which("objdump") is None:
        raise SystemExit("taylor_codegen needs objdump (binutils) to read the code")
    dump = Path(tempfile.mkdtemp(prefix="taylor_codegen_"))
    # XLA reads its flags when its CPU backend starts: before any computation.
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} --xla_dump_to={dump}"
    enable_fast_cpu_loops()
    jax.config.update("jax_enable_x64", True)
    order = compile_one_tile(options.tile, options.tol)
    instructions, called = disassembly(list(dump.glob("*lambda*.o")))
    print(
        f"double pendulum, tile of {options.tile}, tol {options.tol:.0e}, order {order}"
    )
    print(f"  kernel: {len(instructions)} instructions (static counts below)")
    for name, count in sorted(census(instructions).items()):
        print(f"  {name:12s} {count}")
    print(f"  call sites out of the kernel: {dict(collections.Counter(called))}")
    summing = []
    for first, last in innermost_loops(instructions):
        counts = census(instructions[first : last + 1])
        if counts["fma ymm"] + counts["fma scalar"] > 0:
            summing.append(counts)
    fused = sum((c for c in summing), collections.Counter())
    print(
        f"  innermost loops with multiply-adds: {len(summing)}; in them "
        f"{fused['fma ymm']} on ymm, {fused['fma xmm']} on xmm, "
        f"{fused['fma scalar']} scalar"
    )
    shutil.rmtree(dump)


if __name__ == "__main__":
    main()
