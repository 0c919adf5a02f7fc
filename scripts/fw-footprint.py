#!/usr/bin/env python3
"""Flash, static RAM and worst-case stack of a Cortex-M firmware ELF (thumbv7em).

    scripts/fw-footprint.py ELF [ELF ...] [--markdown] [--tree]

Flash: the allocated sections stored in flash (vector table, .text, .rodata, .data's load
image). Static RAM: .data + .bss + .uninit. Stack: a static analysis of the disassembly
(`llvm-objdump -d`), since the stable toolchain has no `-Z emit-stack-sizes` for thumbv7em:
each function's frame is what its pushes (4 B per core register, 8 B per D register) and its
`sub sp, #n` take; its depth is its frame plus the deepest callee reached by `bl` (a tail
call `b` to another function's entry adds the callee without the caller's frame, since the
caller popped it; counted with it anyway, an upper bound). Reset's depth is the main path;
each vector-table handler adds its own depth plus the exception frame the core stacks
(104 B with the FPU context of a Cortex-M4F). Worst case = main path + every distinct
handler nested once (an upper bound: handlers of one priority level do not nest).

An indirect call `blx rN` is followed when rN holds a function's address the same function
loaded from its literal pool (`ldr rN, [pc, #k]`) or built with `movw`/`movt` (what
`opt-level = "z"` does: it keeps a callee's address in a register to call it several
times); the register is tracked through `mov` in a linear pass, and forgotten when another
instruction writes it. Other indirect calls (function pointers, trait objects) and recursion
cannot be followed: the script lists them; a figure with such a function on its path is a
lower bound for that path and marked with `+`.
"""

import re
import subprocess
import sys
from functools import lru_cache

EXC_FRAME = 104  # 8 core words + 18 FP words (S0-S15, FPSCR, reserved), Cortex-M4F

FUNC = re.compile(r"^([0-9a-f]+) <(.+)>:$")
INSN = re.compile(r"^\s*([0-9a-f]+):\s+(\S+)\s*(.*)$")
REGLIST = re.compile(r"\{([^}]*)\}")
TARGET = re.compile(r"0x([0-9a-f]+) <(.+?)(\+0x[0-9a-f]+)?>")


def sections(elf):
    """Name -> (size, addr, file offset, type) from llvm-readelf -S."""
    out = subprocess.run(["llvm-readelf", "-S", "-W", elf], capture_output=True, text=True, check=True).stdout
    res = {}
    for line in out.splitlines():
        m = re.match(r"\s*\[\s*\d+\]\s+(\S+)\s+(\S+)\s+([0-9a-f]+)\s+([0-9a-f]+)\s+([0-9a-f]+)\s+\S+\s+(\S*)", line)
        if m:
            name, _typ, addr, off, size, flags = m.groups()
            res[name] = (int(size, 16), int(addr, 16), int(off, 16), _typ)
    return res


def reg_count(text):
    m = REGLIST.search(text)
    if not m:
        return 0
    n = 0
    for part in m.group(1).split(","):
        part = part.strip()
        if "-" in part:
            a, b = part.split("-")
            n += int(b.strip()[1:]) - int(a.strip()[1:]) + 1
        elif part:
            n += 1
    return n


REG = re.compile(r"^(r\d+|sb|sl|fp|ip|lr)\b")
LITERAL = re.compile(r"\[pc, #-?\d+\]\s*@ 0x([0-9a-f]+)")
IMM = re.compile(r"#(0x[0-9a-f]+|\d+)")
# Instructions whose first operand is not a register they write.
NO_WRITE = ("str", "cmp", "cmn", "tst", "teq", "b", "push", "pop", "it", "vst", "stm", "vpush", "vpop", "nop", "dsb", "isb", "dmb", "cps", "wfi", "wfe", "sev", "bkpt", "udf", "svc", "pld")


class Words:
    """32-bit words of the ELF's allocated sections, by address (literal pools)."""

    def __init__(self, elf, secs):
        self.elf = elf
        self.secs = [(addr, size, off) for (size, addr, off, typ) in secs.values() if addr and typ != "NOBITS"]
        self.data = open(elf, "rb").read()

    def __call__(self, a):
        for addr, size, off in self.secs:
            if addr <= a and a + 4 <= addr + size:
                o = off + a - addr
                return int.from_bytes(self.data[o : o + 4], "little")
        return None


def parse(elf, words=None):
    """Functions: addr -> dict(name, frame, calls, tails, indirect, dynamic)."""
    out = subprocess.run(
        ["llvm-objdump", "-d", "--no-show-raw-insn", "--demangle", elf],
        capture_output=True, text=True, check=True,
    ).stdout
    funcs = {}
    cur = None
    regs = {}
    pending = []  # (function, address) of `blx rN` with rN = address, checked once all are known
    for line in out.splitlines():
        m = FUNC.match(line)
        if m and m.group(2).startswith("$") and cur is not None:
            # A mapping symbol ($t code, $d data: literal pools inside a function, frequent
            # at opt-level "z"): the function goes on.
            continue
        if m:
            addr = int(m.group(1), 16)
            cur = funcs.setdefault(addr, dict(name=m.group(2), frame=0, calls=set(), tails=set(), indirect=False, dynamic=False))
            regs = {}
            continue
        if cur is None:
            continue
        m = INSN.match(line)
        if not m:
            continue
        op, args = m.group(2), m.group(3)
        base = op.split(".")[0]
        dst = REG.match(args)
        if base == "blx" and dst and not "0x" in args:
            v = regs.get(dst.group(1))
            if v is not None:
                pending.append((cur, v & ~1))
            else:
                cur["indirect"] = True
            continue
        if dst and not base.startswith(NO_WRITE):
            r = dst.group(1)
            lit = LITERAL.search(args)
            imm = IMM.search(args)
            if base == "ldr" and lit and words is not None:
                regs[r] = words(int(lit.group(1), 16))
            elif base == "mov" and REG.match(args.split(",", 1)[1].strip() if "," in args else ""):
                regs[r] = regs.get(REG.match(args.split(",", 1)[1].strip()).group(1))
            elif base == "movw" and imm:
                regs[r] = int(imm.group(1), 0)
            elif base == "movt" and imm and regs.get(r) is not None:
                regs[r] = (regs[r] & 0xFFFF) | (int(imm.group(1), 0) << 16)
            else:
                regs.pop(r, None)
                if base == "ldrd":
                    second = REG.match(args.split(",", 1)[1].strip())
                    if second:
                        regs.pop(second.group(1), None)
                elif base.startswith("ldm"):
                    regs.clear()
        elif base == "pop":
            regs.clear()
        if base in ("str", "strd") and re.search(r"\[sp, #-(\d+)\]!", args):
            # A push by pre-indexed store (one register, as the outliner and -Oz save one).
            cur["frame"] += int(re.search(r"\[sp, #-(\d+)\]!", args).group(1))
        elif op in ("push", "push.w", "stmdb") and ("sp!" in args or op.startswith("push")):
            cur["frame"] += 4 * reg_count(args)
        elif op in ("vpush", "vpush.64"):
            cur["frame"] += 8 * reg_count(args)
        elif op.startswith("sub") and re.match(r"sp,\s*(sp,\s*)?#", args):
            cur["frame"] += int(re.search(r"#(\d+)", args).group(1))
        elif op.startswith("sub") and args.startswith("sp,"):
            cur["dynamic"] = True
        elif op in ("bl", "blx") and "0x" in args:
            t = TARGET.search(args)
            if t:
                cur["calls"].add(int(t.group(1), 16))
        elif op == "blx":
            cur["indirect"] = True
        elif op in ("b", "b.w") and "0x" in args:
            t = TARGET.search(args)
            # A branch to another function's entry; not to a mapping symbol ($t after a
            # literal pool: the same function).
            if t and t.group(3) is None and t.group(2) != cur["name"] and not t.group(2).startswith("$"):
                cur["tails"].add(int(t.group(1), 16))
    for f, a in pending:
        if a in funcs:
            f["calls"].add(a)
        else:
            f["indirect"] = True
    return funcs


def vectors(elf, secs):
    """Handler addresses from the vector table (entries 1.. are Reset and the exceptions)."""
    size, _addr, off, _t = secs[".vector_table"]
    with open(elf, "rb") as f:
        f.seek(off)
        data = f.read(size)
    words = [int.from_bytes(data[i : i + 4], "little") for i in range(0, len(data), 4)]
    return [w & ~1 for w in words[1:] if w]


def analyse(elf):
    secs = sections(elf)
    funcs = parse(elf, Words(elf, secs))
    unknown = set()

    @lru_cache(maxsize=None)
    def depth(a, stack=()):
        f = funcs.get(a)
        if f is None:
            return 0, True
        if a in stack:
            unknown.add(f["name"] + " (recursion)")
            return 0, True
        st = stack + (a,)
        lower = f["indirect"] or f["dynamic"]
        if f["indirect"]:
            unknown.add(f["name"] + " (indirect call)")
        if f["dynamic"]:
            unknown.add(f["name"] + " (variable frame)")
        best = 0
        for c in f["calls"] | f["tails"]:
            d, lb = depth(c, st)
            if d > best:
                best = d
            lower |= lb
        return f["frame"] + best, lower

    vec = vectors(elf, secs)
    reset = vec[0]
    main_depth, main_lb = depth(reset)
    handlers = {}
    for a in vec[1:]:
        if a in handlers or a == reset:
            continue
        d, lb = depth(a)
        handlers[a] = (d + EXC_FRAME, lb)
    flash_secs = [".vector_table", ".text", ".rodata", ".data", ".gnu.sgstubs"]
    flash = sum(secs[s][0] for s in flash_secs if s in secs)
    ram = sum(secs[s][0] for s in (".data", ".bss", ".uninit") if s in secs and secs[s][3] != "NULL")
    deepest = max(handlers.values(), default=(0, False))
    worst = main_depth + sum(d for d, _ in handlers.values())
    return dict(
        elf=elf,
        flash=flash,
        text=secs.get(".text", (0,))[0],
        rodata=secs.get(".rodata", (0,))[0],
        ram=ram,
        main=main_depth,
        main_lb=main_lb,
        handler=deepest[0],
        handler_lb=deepest[1],
        worst=worst,
        worst_lb=main_lb or any(lb for _, lb in handlers.values()),
        unknown=sorted(unknown),
        funcs=funcs,
        reset=reset,
        depth=depth,
    )


def tree(r, a=None, indent=0, seen=None):
    """The deepest call path from `a` (default Reset)."""
    funcs, depth = r["funcs"], r["depth"]
    a = r["reset"] if a is None else a
    while a in funcs:
        f = funcs[a]
        print(f"{'  ' * indent}{depth(a)[0]:6d} {f['frame']:6d}  {f['name'][:100]}")
        nxt = max(f["calls"] | f["tails"], key=lambda c: depth(c)[0], default=None)
        if nxt is None:
            break
        a = nxt
        indent += 1


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    md = "--markdown" in sys.argv
    if not args:
        print(__doc__)
        sys.exit(2)
    # Only ELF files (a glob over a target directory also matches the `.d` dependency files).
    def is_elf(path):
        try:
            with open(path, "rb") as f:
                return f.read(4) == b"\x7fELF"
        except OSError:
            return False

    missing = [e for e in args if not is_elf(e)]
    for e in missing:
        if not e.endswith(".d"):
            print(f"{e}: not an ELF file, skipped", file=sys.stderr)
    rows = [analyse(e) for e in args if is_elf(e)]
    plus = lambda lb: "+" if lb else ""
    if md:
        print(
            "| image | flash B (.text / .rodata) | static RAM B | stack B: main path / deepest handler"
            " / all nested | RAM B: static + all-nested stack |"
        )
        print("|---|---|---|---|---|")
    for r in rows:
        name = r["elf"].rsplit("/", 1)[-1]
        if md:
            print(
                f"| {name} | {r['flash']:,} ({r['text']:,} / {r['rodata']:,}) | {r['ram']:,} | "
                f"{r['main']:,}{plus(r['main_lb'])} / {r['handler']:,}{plus(r['handler_lb'])} / "
                f"{r['worst']:,}{plus(r['worst_lb'])} | {r['ram'] + r['worst']:,}{plus(r['worst_lb'])} |"
            )
        else:
            print(
                f"{name}: flash {r['flash']} B (.text {r['text']}, .rodata {r['rodata']}), static RAM {r['ram']} B, "
                f"stack main path {r['main']}{plus(r['main_lb'])} B, deepest handler {r['handler']}{plus(r['handler_lb'])} B "
                f"(with exception frame), all handlers nested {r['worst']}{plus(r['worst_lb'])} B"
            )
            for u in r["unknown"]:
                print(f"    not followed: {u}")
        if "--tree" in sys.argv:
            tree(r)


if __name__ == "__main__":
    try:
        main()
    except BrokenPipeError:  # output cut short (`| head`)
        sys.stderr.close()
