#!/usr/bin/env python3
"""Loop-body sizes of a JIT-compiled shader from a callgrind profile (docs/pathtracing.md).

lavapipe runs a shader's loop body in full (masked) on every iteration, so the instructions
executed exactly N times, where N is the iteration count of a loop, are that loop's body. Run

    LP_NUM_THREADS=1 valgrind --tool=callgrind --dump-instr=yes --smc-check=all-non-file \
        --callgrind-out-file=OUT voxdag render F --pt --spp 3 --size 160x90 --out x.png

then `tools/callgrind-loops.py OUT`: for the costliest unnamed JIT functions (lavapipe's
pipelines, named by address), the execution counts that cover the most instructions, each with
how many instructions ran that often (the body size) and their product.
"""
import collections
import re
import sys


def parse(path):
    """Self cost per (function id, instruction address), the names of the ids, and the ids of
    the functions of code without an object file (JIT code)."""
    costs = collections.defaultdict(collections.Counter)
    # Compressed names: `ob=(id) name` / `fn=(id) name` define an id, later lines give the id
    # alone; `cob`/`cfn` (a call's target) define ids without changing the current object or
    # function.
    table = {"ob": {}, "fn": {}}
    current = {"ob": None, "fn": None}
    jit = set()
    addr = 0
    skip_next = False  # the cost line after `calls=` is the callee's inclusive cost
    for raw in open(path):
        line = raw.rstrip("\n")
        m = re.match(r"(c?)(ob|fn)=\((\d+)\)(?: (.*))?", line)
        if m:
            call, kind, ident, name = m.groups()
            if name:
                table[kind][ident] = name
            if not call:
                current[kind] = ident
                if kind == "fn" and table["ob"].get(current["ob"]) == "???":
                    jit.add(ident)
            continue
        if line.startswith("calls="):
            skip_next = True
            continue
        if not line or line[0] not in "0123456789+-*":
            continue
        parts = line.split()
        tok = parts[0]
        if tok.startswith("+"):
            addr += int(tok[1:], 0)
        elif tok.startswith("-"):
            addr -= int(tok[1:], 0)
        elif tok != "*":
            addr = int(tok, 0)
        if skip_next:
            skip_next = False
            continue
        if len(parts) >= 3 and current["fn"] is not None:
            costs[current["fn"]][addr] += int(parts[2])
    return costs, table["fn"], jit


def main():
    costs, names, jit = parse(sys.argv[1])
    ranked = sorted(((sum(costs[fid].values()), fid) for fid in jit), reverse=True)
    for total, fid in ranked[:2]:
        print(f"{names[fid]}: {total} instructions")
        sizes = collections.Counter(costs[fid].values())
        top = sorted(sizes.items(), key=lambda kv: -kv[0] * kv[1])[:6]
        print("  executions  body  product")
        for count, body in top:
            print(f"  {count:>10}  {body:>4}  {count * body}")


if __name__ == "__main__":
    main()
