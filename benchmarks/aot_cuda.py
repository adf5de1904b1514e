#!/usr/bin/env python
"""Compile a run's CUDA kernels ahead of time, on a machine without a GPU.

Warp compiles each kernel module for CUDA with NVRTC, which ships inside ``warp-lang`` and
needs neither a GPU nor a driver. A first CUDA run of grisx pays that compilation per module
and per set of material kinds in a scene (``render.restcv.kinds_0_1``, ...): seconds for
the path tracer, 15-30 s for most ReSTIR modules and about 3 minutes for Suffix ReSTIR's
(NVRTC, one core of this 2-core machine). On a rented GPU whose time is counted, that is
time spent not rendering. This script runs any command on the CPU with Warp's module loader
wrapped so that every module the command loads for the CPU is *also* compiled to an
``sm_ARCH`` cubin in the kernel cache (``WARP_CACHE_PATH``), under the same module hash the
GPU will look for (the hash does not depend on the device; the CPU's ``block_dim = 1``
variant is the only difference, and the cubin is built for the module's own block size).
``--pack`` collects the cubins and their metadata into a tarball; unpack it into the GPU
machine's ``WARP_CACHE_PATH`` and the first CUDA run finds every module cached.

Run the command with the same scenes, methods and params as the CUDA run (sizes and frame
counts may be tiny: they do not enter the hash)::

    export WARP_CACHE_PATH=/tmp/wcache
    python benchmarks/aot_cuda.py --arch 90 -- benchmarks/restir_every_scene.py --device cpu --jobs 2
    python benchmarks/aot_cuda.py --arch 90 --pack wcache_sm90.tar.xz

and on the GPU machine::

    mkdir -p ~/wcache && tar xJf wcache_sm90.tar.xz -C ~/wcache && export WARP_CACHE_PATH=~/wcache

Only cubins are built: Warp loads a cubin when the driver is older than Warp's CUDA toolkit
(the usual case), and PTX otherwise; set ``warp.config.cuda_output = "cubin"`` where it is not.
The hook reaches into Warp's private ``Module._compile`` (Warp 1.19): it is a tool for
benchmarks, not part of the library. Worker processes inherit it through a ``sitecustomize``
on ``PYTHONPATH``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

ENV_ARCH = "GRISX_AOT_ARCH"


def install_hook(arch: int) -> None:
    """Wrap ``warp.Module.load``: after each load, compile the module's cubin for ``sm_arch`` too."""
    from warp._src import context

    original = context.Module.load
    done: set[str] = set()

    def load(self, device, block_dim=None, *args, **kwargs):
        # Hash the CUDA variant *before* the CPU build: building a module's adjoints for the CPU
        # changes what Warp 1.19 hashes afterwards, and a cubin compiled under that later hash is
        # never found by a GPU process (which hashes a fresh module). Measured: kinds_0_2 of
        # suffix_restir hashed 4a32ffc fresh and 34d11f8 after a CPU load.
        self.get_module_hash(None)
        exec_ = original(self, device, block_dim, *args, **kwargs)
        key = f"{self.name} {self.get_module_hash(None).hex()[:7]}"
        if key not in done:
            done.add(key)
            t0 = time.perf_counter()
            try:
                built = self._compile(None, None, output_arch=arch, use_ptx=False)
            except Exception as exc:  # a module that cannot build for CUDA: the GPU run will say so
                print(f"aot_cuda: {self.name}: {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
            else:
                if built:
                    print(f"aot_cuda: {self.name} sm_{arch} in {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
        return exec_

    context.Module.load = load


def pack(cache_root: Path, arch: int, out: Path) -> int:
    """Tar every ``*.sm{arch}.cubin`` of the cache with its module's ``.meta`` (paths relative to the cache root)."""
    members = []
    for cubin in sorted(cache_root.glob(f"*/wp_*/*.sm{arch}.cubin")):
        meta = cubin.with_name(cubin.name.split(f".sm{arch}.")[0] + ".meta")
        if meta.exists():
            members += [cubin, meta]
    with tarfile.open(out, "w:xz") as tar:
        for m in members:
            tar.add(m, arcname=str(m.relative_to(cache_root)))
    return len(members) // 2


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    cmd = argv[argv.index("--") + 1:] if "--" in argv else []
    own = argv[: argv.index("--")] if "--" in argv else argv
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--arch", type=int, default=90, help="CUDA compute capability of the target GPU (90: H100/H200)")
    ap.add_argument("--pack", type=Path, default=None, help="write the cache's cubins for --arch (and their .meta) to this .tar.xz")
    args = ap.parse_args(own)
    if not cmd and args.pack is None:
        ap.error("give a command after '--', or --pack")
    if "WARP_CACHE_PATH" not in os.environ:
        ap.error("set WARP_CACHE_PATH: the kernel cache to fill (and to carry to the GPU machine)")
    if cmd:
        with tempfile.TemporaryDirectory() as hook_dir:
            Path(hook_dir, "sitecustomize.py").write_text(
                "import os, sys\n"
                f"if os.environ.get({ENV_ARCH!r}):\n"
                f"    sys.path.insert(0, {str(Path(__file__).resolve().parent)!r})\n"
                "    import aot_cuda\n"
                f"    aot_cuda.install_hook(int(os.environ[{ENV_ARCH!r}]))\n")
            env = dict(os.environ, **{ENV_ARCH: str(args.arch)})
            env["PYTHONPATH"] = os.pathsep.join([hook_dir, str(Path.cwd())] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
            rc = subprocess.call([sys.executable] + cmd, env=env)
        if rc != 0:
            return rc
    if args.pack is not None:
        n = pack(Path(os.environ["WARP_CACHE_PATH"]), args.arch, args.pack)
        print(f"aot_cuda: packed {n} modules (sm_{args.arch}) into {args.pack} ({args.pack.stat().st_size / 1e6:.1f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
