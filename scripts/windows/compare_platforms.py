#!/usr/bin/env python3
# Compares what the Linux build and the Windows build made from the same inputs (native/python/test_module_platform.py
# and blender_tests/extension/test_extension_install.py --out-dir): every file of the Linux folder must be in the
# Windows folder. Exports and scene digests must be byte-identical: both builds compile the same sources against the
# same library versions, and reading, editing and writing splats is arithmetic IEEE 754 fixes. Rendered pixels
# (.npy) must agree within TOLERANCES: Embree is held to one instruction set on both sides, but the path tracer calls
# sinf, cosf, expf and powf, whose last bits differ between glibc and MinGW's C runtime; everything else is the same.
#   scripts/windows/compare_platforms.py LINUX_DIR WINDOWS_DIR
# Prints one line per file with its largest difference; exit status 1 when any file is missing or disagrees.
import os
import sys

import numpy as np

# Renders: the largest difference of a pixel channel allowed between the platforms, relative to max(1, |value|)
# (linear radiance and alpha; a last-bit difference of a value near 1 is about 6e-8), and the share of channels
# allowed to differ at all. Measured at 61 x 45, 4 samples, isa=sse4.2: the module's render_rgba.npy 8.9e-8 at most in
# 5.5 % of the channels, Blender 4.2's blender_render_rgba.npy 1.2e-7 in 0.05 %; the bounds are about three times that.
TOLERANCES = {"render_rgba.npy": (3e-7, 0.15), "blender_render_rgba.npy": (3e-7, 0.002)}


def compare_arrays(name, a, b):
    if a.shape != b.shape:
        return f"{name}: shape {a.shape} on Linux, {b.shape} on Windows"
    if np.array_equal(a, b, equal_nan=True):
        print(f"{name}: bit-identical ({a.size} values)")
        return None
    differ = ~((a == b) | (np.isnan(a) & np.isnan(b)))
    a64, b64 = a.astype(np.float64), b.astype(np.float64)
    largest = float(np.nanmax(np.abs(a64 - b64) / np.maximum(1.0, np.abs(a64))))
    share = float(differ.mean())
    print(f"{name}: {int(differ.sum())} of {a.size} values differ ({share:.4%}), the largest by {largest:.3g} "
          "(relative to max(1, |value|))")
    limit, limit_share = TOLERANCES.get(name, (0.0, 0.0))
    if largest > limit or share > limit_share:
        return f"{name}: differs beyond the tolerance (largest {limit:g}, share {limit_share:.2%})"
    return None


def main():
    linux, windows = sys.argv[1:3]
    problems = []
    names = sorted(os.listdir(linux)) if os.path.isdir(linux) else []
    if not names:
        problems.append(f"{linux} holds nothing to compare")
    for name in names:
        other = os.path.join(windows, name)
        if not os.path.exists(other):
            problems.append(f"{name}: made on Linux, missing on Windows ({windows})")
            continue
        if name.endswith(".npy"):
            problem = compare_arrays(name, np.load(os.path.join(linux, name)), np.load(other))
        elif name.endswith(".npz"):
            a, b = np.load(os.path.join(linux, name)), np.load(other)
            problem = None
            for key in a.files:
                problem = problem or compare_arrays(f"{name}[{key}]", a[key], b[key])
        else:
            with open(os.path.join(linux, name), "rb") as f:
                a = f.read()
            with open(other, "rb") as f:
                b = f.read()
            if a == b:
                print(f"{name}: byte-identical ({len(a)} bytes)")
                problem = None
            else:
                first = next((i for i, (x, y) in enumerate(zip(a, b)) if x != y), min(len(a), len(b)))
                problem = f"{name}: {len(a)} bytes on Linux, {len(b)} on Windows, first difference at byte {first}"
        if problem:
            problems.append(problem)
    for problem in problems:
        print(f"compare_platforms: {problem}")
    print(f"{len(names) - len(problems)} passed, {len(problems)} failed")
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
