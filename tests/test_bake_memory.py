"""``bake.py --memory-mb`` bounds a bake's memory whatever the texture (exporters.bake.job, .evaluate,
exporters.image_input): peak RSS measured in subprocesses (``RUSAGE_CHILDREN``), and images whose header claims
more texels than the budget decodes refused before decoding."""

from __future__ import annotations

import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

from exporters import texel_table
from exporters.colorimetry import srgb_decode
from tests.addon_scene import write_image

ROOT = Path(__file__).resolve().parents[1]
BAKE = ROOT / "blender_addon" / "bake.py"
TABLE = ROOT / "blender_addon" / "models" / "skin_inversion_table.npz"
BUDGET_MB = 160
OUTSIDE_COLOURS = 2000
#: Distinct colours of the texture baked with ``--exact`` (the model evaluates ~500 colours per CPU-second).
EXACT_COLOURS = 4000


def random_texture(size: int, outside: int, seed: int = 0) -> np.ndarray:
    """(size, size, 3) uint8 sRGB codes drawn at random: ``outside`` distinct colours outside the fast-path table
    (looked up at the nearest skin colour; distinct with near certainty) and the rest drawn from the colours
    inside it (about 300,000 distinct colours)."""
    rng = np.random.default_rng(seed)
    codes = rng.integers(0, 256, (3 * size * size, 3), dtype=np.uint8)
    inside = texel_table.load(TABLE).locate(srgb_decode(codes / 255.0).astype(np.float32))[0]
    draws = rng.integers(0, inside.sum(), size * size - outside)
    picked = np.concatenate([codes[~inside][:outside], codes[inside][draws]])
    rng.shuffle(picked)
    return picked.reshape(size, size, 3)


def peak_rss_mb(*args: str) -> tuple[float, subprocess.CompletedProcess]:
    """Peak resident memory (MiB) of ``bake.py args`` run alone in a child process (``ru_maxrss`` of a child
    that runs it and reports its own children's peak, so earlier children of this process do not count)."""
    probe = ("import resource, subprocess, sys; p = subprocess.run(sys.argv[1:]); "
             "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss); sys.exit(p.returncode)")
    proc = subprocess.run([sys.executable, "-c", probe, sys.executable, str(BAKE), *args], capture_output=True,
                          text=True, timeout=600, cwd=str(ROOT))
    return int(proc.stdout.strip().splitlines()[-1]) / 1024.0, proc


@pytest.fixture(scope="module")
def textures(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("textures")
    rng = np.random.default_rng(1)
    palette = rng.integers(0, 256, (EXACT_COLOURS, 3), dtype=np.uint8)
    return {"big": write_image(folder / "random1k.png", random_texture(1024, OUTSIDE_COLOURS), "uint8"),
            "few": write_image(folder / "few1k.png", palette[rng.integers(0, EXACT_COLOURS, (1024, 1024))], "uint8"),
            "tiny": write_image(folder / "tiny.png", rng.integers(0, 256, (8, 8, 3), dtype=np.uint8), "uint8")}


def test_peak_memory_of_a_random_colour_texture_stays_within_the_budget(textures, tmp_path):
    """1024^2 texels of random colours (~300,000 distinct, 2,000 outside the table): the peak RSS above a bake of
    8 x 8 texels with the same options (the libraries, the model session, the table) stays within --memory-mb;
    and so does an exact bake (--exact: every distinct colour through the model, in chunks) of 1024^2 texels of
    4,000 random colours."""
    cases = (("big", (), "texels_outside_table"), ("few", ("--exact",), "texels_evaluated_exactly"))
    for name, extra, counted in cases:
        options = ("--memory-mb", str(BUDGET_MB), "--threads", "1", "--quiet", *extra)
        base, proc = peak_rss_mb("--albedo", str(textures["tiny"]), "--out", str(tmp_path / f"tiny_{name}"), *options)
        assert proc.returncode == 0, proc.stderr
        peak, proc = peak_rss_mb("--albedo", str(textures[name]), "--out", str(tmp_path / name), *options)
        assert proc.returncode == 0, proc.stderr
        record = next((tmp_path / name).glob("*_maps.json")).read_text()
        assert f'"{counted}": 0' not in record, record
        assert peak - base <= BUDGET_MB, f"{name}: peak {peak:.0f} MiB, fixed {base:.0f} MiB, budget {BUDGET_MB} MiB"


def _png_header_only(path: Path, width: int, height: int) -> Path:
    """A PNG whose header claims width x height RGB texels (its pixel data is a few bytes: never decoded here)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\0" * 64))
                     + chunk(b"IEND", b""))
    return path


@pytest.mark.parametrize(("size", "budget"), [(65535, None), (1024, 64)])
def test_an_image_larger_than_the_budget_is_refused_before_decoding(tmp_path, textures, size, budget):
    image = _png_header_only(tmp_path / "huge.png", size, size) if budget is None else textures["big"]
    args = ["--albedo", str(image), "--out", str(tmp_path / "maps")] + (["--memory-mb", str(budget)] if budget else [])
    peak, proc = peak_rss_mb(*args)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
    assert "--memory-mb" in proc.stderr and f"{size} x {size}" in proc.stderr
    assert peak < 1024, f"{peak:.0f} MiB: the image was decoded"
    assert not (tmp_path / "maps").exists()


def test_a_small_image_bakes_under_a_small_budget(textures, tmp_path):
    """The budget counts what an image touches: 8 x 8 texels decode in far less than the 8-bit colour bitmap (48 MiB,
    which a budget counting it would refuse with exit 2), so a 16 MiB budget bakes them, to the same maps as the
    default budget."""
    from exporters.maps import read_exr

    small, default = tmp_path / "small", tmp_path / "default"
    _, proc = peak_rss_mb("--albedo", str(textures["tiny"]), "--out", str(small), "--memory-mb", "16", "--quiet")
    assert proc.returncode == 0, proc.stderr
    _, proc = peak_rss_mb("--albedo", str(textures["tiny"]), "--out", str(default), "--quiet")
    assert proc.returncode == 0, proc.stderr
    names = sorted(p.name for p in small.glob("*.exr"))
    assert names and names == sorted(p.name for p in default.glob("*.exr"))
    for name in names:
        np.testing.assert_array_equal(read_exr(small / name)[0], read_exr(default / name)[0], err_msg=name)
