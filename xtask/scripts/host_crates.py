#!/usr/bin/env python3
"""The dependencies that run only while compiling, and whether Cargo.toml builds them unoptimised.

`[profile.dev.package."*"] opt-level = 3` outranks `[profile.dev.build-override]`, so without a
named entry each procedural macro, its parser (three versions of syn) and each build-script
helper is compiled at opt-level 3, which costs the CI's build minutes and gains nothing.
Cargo.toml names every such crate with `opt-level = 0`; this script computes the set from
`cargo metadata` (packages reached from the workspace only through build-dependencies or
procedural macros, on this platform) and compares it with Cargo.toml's entries.

    python3 xtask/scripts/host_crates.py          # print the entries Cargo.toml should hold
    python3 xtask/scripts/host_crates.py --check  # exit 1 if Cargo.toml's entries differ

`.ci/run` runs the check, so a dependency update that adds or drops such a crate names it.
"""

import json
import platform
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def host_only_crates() -> list[str]:
    target = f"{platform.machine()}-unknown-linux-gnu"
    out = subprocess.run(
        ["cargo", "metadata", "--format-version", "1", "--locked", "--filter-platform", target],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    meta = json.loads(out)
    packages = {p["id"]: p for p in meta["packages"]}
    nodes = {n["id"]: n for n in meta["resolve"]["nodes"]}

    def is_proc_macro(pid: str) -> bool:
        return any("proc-macro" in t["kind"] for t in packages[pid]["targets"])

    # What the compiled programs link: the workspace and everything reached from it through
    # normal and dev dependencies, stopping at procedural macros.
    linked, host, stack = set(), set(), list(meta["workspace_members"])
    while stack:
        pid = stack.pop()
        if pid in linked:
            continue
        linked.add(pid)
        for dep in nodes[pid]["deps"]:
            for kind in dep["dep_kinds"]:
                if kind["kind"] == "build" or is_proc_macro(dep["pkg"]):
                    host.add(dep["pkg"])
                else:
                    stack.append(dep["pkg"])
    # What runs on the compiling machine: those crates and their own dependencies.
    reached, stack = set(), list(host)
    while stack:
        pid = stack.pop()
        if pid in reached:
            continue
        reached.add(pid)
        stack.extend(
            d["pkg"] for d in nodes[pid]["deps"] if all(k["kind"] != "dev" for k in d["dep_kinds"])
        )
    names = lambda ids: {packages[p]["name"] for p in ids}  # noqa: E731
    # `cargo metadata` resolves optional dependencies that no build here turns on; `cargo tree`
    # lists what is compiled, and an entry naming anything else draws a warning from cargo.
    tree = subprocess.run(
        ["cargo", "tree", "--workspace", "--locked", "-e", "normal,build,dev", "--prefix", "none"]
        + ["--format", "{p}", "--target", target],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    compiled = {line.split()[0] for line in tree.splitlines() if line.strip()}
    # A crate also linked into a program keeps the optimised build.
    return sorted((names(reached) - names(linked)) & compiled)


def entries_in_cargo_toml() -> list[str]:
    text = (ROOT / "Cargo.toml").read_text()
    found = re.findall(r"^\[profile\.dev\.package\.([A-Za-z0-9_-]+)\]\nopt-level = 0$", text, re.M)
    return sorted(found)


def main() -> int:
    want = host_only_crates()
    if "--check" not in sys.argv[1:]:
        for name in want:
            print(f"[profile.dev.package.{name}]\nopt-level = 0")
        return 0
    have = entries_in_cargo_toml()
    missing = [n for n in want if n not in have]
    extra = [n for n in have if n not in want]
    if missing or extra:
        print("Cargo.toml's unoptimised build-time crates differ from the dependency graph:")
        if missing:
            print("  missing (add `[profile.dev.package.NAME] opt-level = 0`):", ", ".join(missing))
        if extra:
            print("  no longer build-time only (remove):", ", ".join(extra))
        print("  `python3 xtask/scripts/host_crates.py` prints the entries.")
        return 1
    print(f"build-time crates: {len(have)}, all built unoptimised")
    return 0


if __name__ == "__main__":
    sys.exit(main())
