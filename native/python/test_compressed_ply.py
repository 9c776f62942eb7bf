# SuperSplat's compressed PLY against an independent numpy decoder written from the format's sources (not from our
# C++): ../tests/reference/supersplat_compressed_ply.py (from PlayCanvas engine gsplat-compressed-data.js and
# splat-transform decompress-ply.ts); the writer's bounds from splat-transform src/lib/writers/compressed-chunk.ts.
#   python3 test_compressed_ply.py MODULE_DIR RAYSPLATS_CLI DATA_DIR TMP_DIR
# Reading: the real SuperSplat file must read as this decoder says, within float rounding. Writing: `raysplats convert`
# of a trained INRIA .ply to .compressed.ply must decode (here) to the input within the format's quantisation.
import os
import shutil
import subprocess
import sys
import unittest

# The test command's reporting: skips counted and named, exit 77 (a skip for ctest) when every test skipped.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "lib"))
import unittest_report  # noqa: E402

import numpy as np

MODULE_DIR, CLI, DATA_DIR, TMP_DIR = sys.argv[1:5]
del sys.argv[1:5]
sys.path.insert(0, MODULE_DIR)
# The decoder (one copy, shared with the viewer-agreement reference).
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "reference"))
import _native  # noqa: E402
from supersplat_compressed_ply import SH_C0, decode_compressed, read_ply_elements  # noqa: E402


def read_inria(path):
    v = read_ply_elements(path)["vertex"]
    rest = sorted((name for name in v.dtype.names if name.startswith("f_rest_")), key=lambda s: int(s[7:]))
    rotation = np.stack([v[f"rot_{j}"] for j in range(4)], axis=1).astype(np.float64)
    return {"positions": np.stack([v[a] for a in "xyz"], axis=1).astype(np.float64),
            "rotations": rotation / np.linalg.norm(rotation, axis=1, keepdims=True),
            "scales": np.exp(np.stack([v[f"scale_{j}"] for j in range(3)], axis=1).astype(np.float64)),
            "opacities": 1 / (1 + np.exp(-v["opacity"].astype(np.float64))),
            "f_dc": np.stack([v[f"f_dc_{j}"] for j in range(3)], axis=1).astype(np.float64),
            "f_rest": np.stack([v[name] for name in rest], axis=1).astype(np.float64).reshape(len(v), 3, -1)}


def morton_sorted(d):
    """d's splats in Morton order (10 bits per axis over the centres' bounding box)."""
    p = d["positions"]
    cell = np.clip((p - p.min(axis=0)) / np.maximum(p.max(axis=0) - p.min(axis=0), 1e-30) * 1023, 0, 1023).astype(np.uint64)
    code = np.zeros(len(p), np.uint64)
    for bit in range(10):
        for axis in range(3):
            code |= ((cell[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    order = np.argsort(code, kind="stable")
    return {k: v[order] for k, v in d.items()}


def write_inria(path, d):
    n, rest = len(d["opacities"]), d["f_rest"].reshape(len(d["opacities"]), -1)
    columns = ([d["positions"][:, j] for j in range(3)] + [d["f_dc"][:, j] for j in range(3)] +
               [rest[:, k] for k in range(rest.shape[1])] + [np.log(d["opacities"] / (1 - d["opacities"]))] +
               [np.log(d["scales"][:, j]) for j in range(3)] + [d["rotations"][:, j] for j in range(4)])
    names = (list("xyz") + [f"f_dc_{j}" for j in range(3)] + [f"f_rest_{k}" for k in range(rest.shape[1])] +
             ["opacity"] + [f"scale_{j}" for j in range(3)] + [f"rot_{j}" for j in range(4)])
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\n" +
              "".join(f"property float {name}\n" for name in names) + "end_header\n")
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(np.stack(columns, axis=1).astype("<f4").tobytes())


class CompressedPly(unittest.TestCase):
    def test_guitar_reads_as_the_independent_decoder_says(self):
        path = os.path.join(DATA_DIR, "guitar_supersplat.compressed.ply")
        expected = decode_compressed(path)
        ours = _native.read_splats(path)
        self.assertEqual(len(ours["opacities"]), 90854)
        self.assertEqual(ours["sh_degree"], 0)
        self.assertEqual(ours["warnings"], [])
        # Float rounding of values computed in double and stored as float32 (scales relative: exp).
        np.testing.assert_allclose(ours["positions"], expected["positions"], rtol=0, atol=2e-6)
        np.testing.assert_allclose(ours["scales"], expected["scales"], rtol=2e-6, atol=0)
        np.testing.assert_allclose(ours["opacities"], expected["opacities"], rtol=0, atol=1e-7)
        np.testing.assert_allclose(ours["sh"][:, 0, :], expected["f_dc"], rtol=0, atol=2e-6)
        # Rotations up to sign (q and -q are one rotation).
        dot = np.abs((ours["rotations"].astype(np.float64) * expected["rotations"]).sum(axis=1))
        self.assertGreater(dot.min(), 1 - 1e-6)
        # Upright like the other .ply files (RDF: up is -y). The guitar stands on its stand along y (4.4 units tall,
        # 1.5 wide and deep), and the top tenth of its height (smallest y: the headstock, 0.3 x 0.5 units) is much
        # narrower than the bottom tenth (the stand's feet, 1.5 x 1.2): a reading flipped upside down (as RUB would
        # be) swaps the two. Seen in renders by the CLI, camera up (0, -1, 0): a guitar on a stand, headstock up.
        p = ours["positions"]
        extent = np.ptp(p, axis=0)
        self.assertGreater(extent[1], 2.5 * max(extent[0], extent[2]))
        height = p[:, 1].max() - p[:, 1].min()
        top = p[p[:, 1] < p[:, 1].min() + 0.1 * height]
        bottom = p[p[:, 1] > p[:, 1].max() - 0.1 * height]
        self.assertLess(np.ptp(top[:, [0, 2]], axis=0).max(), 0.5 * np.ptp(bottom[:, [0, 2]], axis=0).min())

    def test_probe_and_memory_estimate_know_the_file(self):
        path = os.path.join(DATA_DIR, "guitar_supersplat.compressed.ply")
        summary = _native.probe_splat_file(path)
        self.assertEqual((summary["format"], summary["count"], summary["sh_degree"]), ("compressed_ply", 90854, 0))

    def test_cli_convert_writes_within_quantisation(self):
        # A trained INRIA scene, put in Morton order here (so that the writer, which keeps an order already that
        # compact, writes the splats in this order and they pair by index), written as an INRIA .ply and converted.
        source = os.path.join(TMP_DIR, "small_sh3_morton.ply")
        original = morton_sorted(read_inria(os.path.join(DATA_DIR, "small_sh3_inria.ply")))
        write_inria(source, original)
        target = os.path.join(TMP_DIR, "small_sh3_from_cli.compressed.ply")
        subprocess.run([CLI, "convert", source, target], check=True, capture_output=True)
        written = decode_compressed(target)
        n = len(original["opacities"])
        self.assertEqual(len(written["opacities"]), n)
        o = original
        chunk = written["chunk"]
        c = np.arange(n) // 256

        def extent(lo, hi):
            return np.stack([(chunk[hi + a] - chunk[lo + a]).astype(np.float64)[c] for a in ("x", "y", "z")], axis=1)

        slack = 1e-6

        def bound(e, levels):
            # Half a step of the chunk's range; a range under 1e-5 is stored as its minimum ([st-write] normalize).
            return np.where(e < 1e-5, e, e / (2 * levels)) + slack

        steps = np.array([2047.0, 1023.0, 2047.0])  # 11-10-11 bits
        pos_err = np.abs(written["positions"] - o["positions"])
        self.assertTrue((pos_err <= bound(extent("min_", "max_"), steps)).all(), pos_err.max())
        log_err = np.abs(np.log(written["scales"]) - np.clip(np.log(o["scales"]), -20, 20))
        self.assertTrue((log_err <= bound(extent("min_scale_", "max_scale_"), steps)).all(), log_err.max())
        colour_extent = np.stack([(chunk["max_" + a] - chunk["min_" + a]).astype(np.float64)[c] for a in "rgb"], 1)
        colour_err = np.abs(written["f_dc"] - o["f_dc"]) * SH_C0
        self.assertTrue((colour_err <= bound(colour_extent, 255.0)).all(), colour_err.max())
        self.assertLessEqual(np.abs(written["opacities"] - o["opacities"]).max(), 1 / 510 + slack)
        # Each of the three smaller components within sqrt(2)/2046, the largest follows: 1 - |dot| <= 6 e^2.
        dot = np.abs((written["rotations"] * o["rotations"]).sum(axis=1))
        self.assertLessEqual((1 - dot).max(), 6 * (np.sqrt(2) / 2046) ** 2 + 1e-7)
        # Higher bands: steps of 1/32 on [-4, 4), the bin's centre read back.
        rest_err = np.abs(written["f_rest"] - np.clip(o["f_rest"], -4, 4))
        self.assertLessEqual(rest_err.max(), 1 / 64 + 1e-6)
        print(f"write -> read, largest errors: position {pos_err.max():.2e}, log scale {log_err.max():.2e}, "
              f"colour {colour_err.max():.2e}, opacity {np.abs(written['opacities'] - o['opacities']).max():.2e}, "
              f"rotation 1-|dot| {(1 - dot).max():.2e}, f_rest {rest_err.max():.2e}")

    def test_cli_converts_under_a_foreign_name_in_the_systems_path_form(self):
        # The command line as a user types it: absolute paths with a drive letter and backslashes on Windows, names no
        # code page holds (on Windows the arguments arrive as UTF-16), and a second run over the first run's file.
        def native_form(path):
            path = os.path.abspath(path)
            return path.replace("/", "\\") if sys.platform == "win32" else path

        folder = os.path.join(TMP_DIR, "cli Ünïcødé 日本語 \U0001F642")
        shutil.rmtree(folder, ignore_errors=True)
        os.makedirs(folder)
        name = "spläts Ελληνικά \U0001F642.spz"
        source = os.path.join(DATA_DIR, "small_sh3_inria.ply")
        for attempt in range(2):
            subprocess.run([CLI, "convert", native_form(source), native_form(os.path.join(folder, name))], check=True,
                           capture_output=True)
        self.assertEqual(os.listdir(folder), [name])
        back = _native.read_splats(os.path.join(folder, name))
        self.assertEqual(len(back["opacities"]), _native.probe_splat_file(source)["count"])


if __name__ == "__main__":
    unittest_report.main()
