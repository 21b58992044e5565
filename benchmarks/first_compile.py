"""What a first run pays before its first frame: compiling and loading every kernel module.

Usage (from the repository root)::

    .venv/bin/python benchmarks/first_compile.py [--device cpu] [--repeats 2] [--no-shipped]

Each try is a new process whose Warp kernel cache is an empty temporary folder (``WARP_CACHE_PATH``),
as on a fresh install: it imports ``sena_warp.kernels`` and runs ``runtime.prewarm`` (every module,
waiting for all). Prints the seconds of the imports and of the load, per try: the shipped builds
(``kernels/built``) load at once; with ``--no-shipped`` every module is compiled, as where no build
fits (another platform or warp-lang). A run after the first loads the cache instead (0.02-0.05 s).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

PROBE = """
import json, sys, time
t0 = time.perf_counter()
from sena_warp.kernels import runtime
if sys.argv[2] == "no-shipped":
    runtime.BUILT = runtime.BUILT.with_name("not_shipped")
t1 = time.perf_counter()
runtime.prewarm(runtime.resolve_device(sys.argv[1]))
print(json.dumps({"import_s": t1 - t0, "compile_s": time.perf_counter() - t1, "modules": len(runtime.loaded())}))
"""


def first_compile(device: str, shipped: bool) -> dict:
    """One try in a new process with an empty kernel cache: its import and load (or compile) seconds."""
    with tempfile.TemporaryDirectory(prefix="sena-warp-cache-") as cache:
        probe = subprocess.run([sys.executable, "-c", PROBE, device, "shipped" if shipped else "no-shipped"],
                               capture_output=True, text=True, check=True, env={**os.environ, "WARP_CACHE_PATH": cache})
    return json.loads(probe.stdout.strip().splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--no-shipped", action="store_true", help="compile every module, as where no shipped build fits")
    args = parser.parse_args()
    for attempt in range(1, args.repeats + 1):
        seen = first_compile(args.device, not args.no_shipped)
        print(f"try {attempt}: imports {seen['import_s']:.2f} s, load {seen['compile_s']:.2f} s "
              f"({seen['modules']} kernel modules on {args.device})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
