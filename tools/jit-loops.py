#!/usr/bin/env python3
"""Loops of lavapipe's native JIT code while a command runs (docs/pathtracing.md).

callgrind (tools/callgrind-loops.py) counts the code LLVM makes under valgrind, which has no
AVX-512; this reads the code the machine really runs. It starts COMMAND, waits --warmup
seconds, samples it with `perf record` for --seconds, dumps the anonymous executable mapping
holding the threads' program counters with gdb, disassembles it with objdump and lists the
loops (backward jumps over at least --min-span bytes) with their instructions, vector
stores to / loads from the stack (spills) and perf samples:

    tools/jit-loops.py OUTDIR -- voxdag -q render F.vdag --pt --spp 40 --size 960x540 --out x.png

The command must still run after the warm-up plus the sampling; it is killed afterwards.
Needs gdb, perf and objdump; the JIT code is the command's only anonymous executable mapping
with a thread in it.
"""
import argparse
import collections
import os
import re
import subprocess
import sys
import time

GDB_SCRIPT = r"""
import gdb
pcs = []
for t in gdb.selected_inferior().threads():
    t.switch()
    pcs.append(int(gdb.parse_and_eval("$pc")) & 0xffffffffffffffff)
for line in gdb.execute("info proc mappings", to_string=True).splitlines():
    f = line.split()
    # Anonymous (no file name) executable mappings.
    if len(f) == 5 and f[0].startswith("0x") and "x" in f[4]:
        lo, hi = int(f[0], 16), int(f[1], 16)
        if any(lo <= p < hi for p in pcs):
            gdb.execute("dump binary memory %s/jit-%x.bin 0x%x 0x%x" % (OUT, lo, lo, hi))
"""


def disassemble(path, base):
    """(address, text) of every instruction of the raw code in `path` loaded at `base`."""
    out = subprocess.run(
        ["objdump", "-D", "-b", "binary", "-m", "i386:x86-64", f"--adjust-vma={base:#x}", path],
        capture_output=True, text=True, check=True,
    ).stdout
    code = []
    for line in out.splitlines():
        m = re.match(r"\s*([0-9a-f]+):\s+(?:[0-9a-f]{2} )+\s*(.*)", line)
        if m and m.group(2):
            code.append((int(m.group(1), 16), m.group(2).strip()))
    return code


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", help="folder for the dump, the disassembly and the samples")
    ap.add_argument("command", nargs=argparse.REMAINDER, help="-- COMMAND ARGS...")
    ap.add_argument("--warmup", type=float, default=6.0, help="seconds before sampling")
    ap.add_argument("--seconds", type=float, default=8.0, help="seconds of perf sampling")
    ap.add_argument("--min-span", type=int, default=0x400, help="smallest loop in bytes")
    a = ap.parse_args()
    command = a.command[1:] if a.command[:1] == ["--"] else a.command
    if not command:
        sys.exit("no command given (tools/jit-loops.py OUT -- COMMAND ...)")
    os.makedirs(a.out, exist_ok=True)
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        time.sleep(a.warmup)
        perf_data = os.path.join(a.out, "perf.data")
        subprocess.run(
            ["perf", "record", "-q", "-e", "cpu-clock", "-F", "2000", "-p", str(proc.pid),
             "-o", perf_data, "--", "sleep", str(a.seconds)],
            check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
        script = os.path.join(a.out, "dump.py")
        with open(script, "w") as f:
            f.write("OUT = %r\n" % os.path.abspath(a.out) + GDB_SCRIPT)
        subprocess.run(["gdb", "-p", str(proc.pid), "-batch", "-ex", f"source {script}"],
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    finally:
        proc.kill()
        proc.wait()
    ips = collections.Counter(
        int(line.split()[0], 16)
        for line in subprocess.run(["perf", "script", "-i", perf_data, "-F", "ip"],
                                   capture_output=True, text=True).stdout.splitlines()
        if line.strip()
    )
    dumps = [f for f in os.listdir(a.out) if re.fullmatch(r"jit-[0-9a-f]+\.bin", f)]
    if not dumps:
        sys.exit("no anonymous executable mapping held a thread (did the command still run?)")
    spill = re.compile(r"%[xyz]mm\d+,-?(0x[0-9a-f]+)?\(%r[sb]p\)$|\(%r[sb]p\)(,%\w+)?,%[xyz]mm")
    for dump in dumps:
        base = int(dump[4:-4], 16)
        code = disassemble(os.path.join(a.out, dump), base)
        with open(os.path.join(a.out, dump[:-4] + ".s"), "w") as f:
            f.writelines("%x %d %s\n" % (at, ips[at], text) for at, text in code)
        total = sum(ips.values())
        print(f"{dump}: {len(code)} instructions, {sum(ips[at] for at, _ in code)} of {total} samples")
        print("  loop (offsets)       instructions  stack vector ops  samples")
        for at, text in code:
            m = re.match(r"j\w+\s+0x([0-9a-f]+)", text)
            target = int(m.group(1), 16) if m else None
            if target is not None and target < at and at - target >= a.min_span:
                body = [(o, t) for o, t in code if target <= o <= at]
                stack = sum(1 for _, t in body if spill.search(t))
                samples = sum(ips[o] for o, _ in body)
                print(f"  {target - base:#7x}..{at - base:#7x}  {len(body):>12}  {stack:>16}  {samples:>7}")


if __name__ == "__main__":
    main()
