#!/usr/bin/env python3
"""Counts `.unwrap()` and `.expect(` in product code (each crate's src/, test modules and
#[cfg(test)] items left out) and fails when a crate goes over its budget in
.ci/unwrap-budget.txt. Lower a budget when you remove some; raising one needs a reason in the
commit (the rule: no unwrap on anything that comes from outside: files, devices, IPC,
network, config).

    python3 .ci/unwrap_budget.py            # check
    python3 .ci/unwrap_budget.py --print    # the current counts, in the budget file's format
"""
import pathlib
import re
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
BUDGET = ROOT / ".ci" / "unwrap-budget.txt"
CALL = re.compile(r"\.(unwrap|expect)\(")


def product_lines(text):
    """Lines of a source file outside `#[cfg(test)]` items (a test module runs to the end of
    the file in this workspace's layout; a single item ends at its closing brace)."""
    out, skip_depth, pending = [], None, False
    for line in text.splitlines():
        stripped = line.strip()
        if skip_depth is not None:
            skip_depth += line.count("{") - line.count("}")
            if skip_depth <= 0 and "}" in line:
                skip_depth = None
            continue
        if stripped.startswith("#[cfg(test)]"):
            pending = True
            continue
        if pending:
            pending = False
            depth = line.count("{") - line.count("}")
            if depth > 0:
                skip_depth = depth
            continue
        if stripped.startswith("//"):
            continue
        out.append(line)
    return out


def counts():
    crates = {}
    for cargo in sorted(ROOT.glob("**/Cargo.toml")):
        if "target" in cargo.parts or cargo.parent == ROOT:
            continue
        src = cargo.parent / "src"
        if not src.is_dir() or cargo.parent.name == "tests":
            continue
        n = 0
        for f in src.rglob("*.rs"):
            if f.name == "tests.rs" or "tests" in f.relative_to(src).parts:
                continue
            n += sum(len(CALL.findall(l)) for l in product_lines(f.read_text()))
        crates[str(cargo.parent.relative_to(ROOT))] = n
    return crates


def main():
    now = counts()
    if "--print" in sys.argv:
        for k, v in now.items():
            print(f"{k} {v}")
        return 0
    budget = {}
    for line in BUDGET.read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            k, v = line.split()
            budget[k] = int(v)
    bad = 0
    for k, v in now.items():
        b = budget.get(k)
        if b is None:
            print(f"unwrap budget: {k} has no budget in {BUDGET.relative_to(ROOT)} (it has {v})")
            bad += 1
        elif v > b:
            print(f"unwrap budget: {k} has {v} unwrap/expect calls in product code, budget {b}")
            bad += 1
    if not bad:
        print("unwrap budget: " + ", ".join(f"{k} {now[k]}/{budget[k]}" for k in now))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
