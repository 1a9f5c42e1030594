"""``make extension``: build and validate the Blender extension zip, with its wheels bundled (BUNDLED).

    python blender_addon/package.py [--out dist] [--platforms linux-x64[,windows-x64,macos-arm64]]
                                    [--wheel-dir .whl] [--no-download]

Steps: fetch the wheels of the pinned versions for each platform and each Python of the supported Blenders
(BUNDLED) with pip (``pip download --only-binary=:all: --no-deps``, cached in
``--wheel-dir``); stage the extension in a fresh folder under ``build/``
(``__init__.py``, ``blender_addon/``, ``exporters/`` and the repository manifest with ``platforms`` and
``wheels`` added); build it with Blender's own extension tool (``blender_ext.py build``, the back-end of
``blender --command extension build``, shipped in the bpy wheel) and validate the zip with it.

Only onnxruntime is bundled: Blender's Python already has numpy, and onnxruntime's InferenceSession runs
with nothing else (docs/research/blender_cycles.md §4).  OpenImageIO is *not* bundled, although Blender 4.2 has
no Python module for it (4.5 and later do): Blender puts the extensions' site-packages *before* its own on
``sys.path``, so a bundled OpenImageIO would replace Blender's own for every add-on and for Cycles, whose
``oslquery`` then fails ("Unregistered type : OpenImageIO_v3_0::TypeDesc", measured on 4.5.15: no OSL Script
node compiles).  The add-on imports OpenImageIO only to read and write image files.  One zip per platform
installs in every supported Blender: Blender computes the manifest's ``python_versions`` from the wheels (3.11
and 3.13 here) and installs only the wheels of the Python it runs (docs/user/install.md).  This file is a
script (it is not shipped in the zip: blender_manifest.toml excludes it) and needs neither bpy imported nor a
Blender binary.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Blender platform -> the pip platform asked for (pip also takes older manylinux/macOS tags: onnxruntime's macOS
#: wheels need macOS 14) and the (prefix, suffix) of a wheel's platform tag that Blender installs there.
PLATFORM_TAGS = {
    "linux-x64": "manylinux_2_28_x86_64",
    "windows-x64": "win_amd64",
    "macos-arm64": "macosx_14_0_arm64",
}
WHEEL_PLATFORMS = {"linux-x64": ("manylinux", "_x86_64"), "windows-x64": ("win", "_amd64"),
                   "macos-arm64": ("macosx", "_arm64")}
#: The Pythons of the supported Blenders: 3.11 (4.2 LTS to 5.0), 3.13 (5.1 and later).
PYTHON_VERSIONS = ("3.11", "3.13")
#: Distribution (pinned in the project venv: pyproject.toml) -> the Pythons its wheels are bundled for.
BUNDLED = {"onnxruntime": PYTHON_VERSIONS}
SHIPPED = ("__init__.py", "blender_addon", "exporters")


def blender_ext_tool() -> Path:
    """blender_ext.py inside the installed bpy package (found without importing bpy)."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("package.py: the bpy module is not installed (pip install bpy==5.0.1)")
    base = Path(list(spec.submodule_search_locations)[0])
    found = sorted(base.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        raise SystemExit(f"package.py: blender_ext.py not found under {base}")
    return found[-1]


def _wheels_for(wheel_dir: Path, dist: str, version: str, platform: str, python: str) -> list[Path]:
    """Wheels of ``dist`` ``version`` in ``wheel_dir`` for the Blender ``platform`` and CPython ``python``."""
    cp = "cp" + python.replace(".", "")
    prefix, suffix = WHEEL_PLATFORMS[platform]
    found = []
    for path in wheel_dir.glob(f"{dist.lower().replace('-', '_')}-{version}-{cp}-{cp}-*.whl"):
        tags = path.name[: -len(".whl")].rsplit("-", 1)[-1].split(".")  # compressed tags: "a.b"
        if any(tag.startswith(prefix) and tag.endswith(suffix) for tag in tags):
            found.append(path)
    return sorted(found)


def fetch_wheel(dist: str, platform: str, python: str, version: str, wheel_dir: Path, download: bool) -> Path:
    """The wheel of ``dist`` for ``platform`` and CPython ``python`` ("3.13") in ``wheel_dir`` (downloaded with
    pip if missing)."""
    existing = _wheels_for(wheel_dir, dist, version, platform, python)
    what = f"{dist} {version} wheel for {platform} and Python {python}"
    if existing:
        return existing[-1]
    if not download:
        raise SystemExit(f"package.py: no {what} in {wheel_dir} (run without --no-download)")
    wheel_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=wheel_dir, prefix=".download-") as tmp:
        cmd = [sys.executable, "-m", "pip", "download", f"{dist}=={version}", "--only-binary=:all:", "--no-deps",
               "--python-version", python, "--implementation", "cp", "--platform", PLATFORM_TAGS[platform],
               "-d", tmp, "--quiet"]
        subprocess.run(cmd, check=True)
        for wheel in Path(tmp).glob("*.whl"):  # whole files only: another build may be reading wheel_dir
            os.replace(wheel, wheel_dir / wheel.name)
    existing = _wheels_for(wheel_dir, dist, version, platform, python)
    if not existing:
        raise SystemExit(f"package.py: pip did not produce the {what}")
    return existing[-1]


def stage(stage_dir: Path, wheels: list[Path], platforms: list[str]) -> Path:
    """Copy what the extension ships into ``stage_dir`` and write its manifest (platforms, wheels)."""
    if stage_dir.exists():
        shutil.rmtree(stage_dir)
    stage_dir.mkdir(parents=True)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in SHIPPED:
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, stage_dir / name, ignore=ignore)
        else:
            shutil.copy2(src, stage_dir / name)
    (stage_dir / "wheels").mkdir()
    for w in wheels:
        shutil.copy2(w, stage_dir / "wheels" / w.name)
    manifest = (ROOT / "blender_manifest.toml").read_text()
    if re.search(r"^(platforms|wheels)\s*=", manifest, flags=re.M):
        raise SystemExit("package.py: the repository manifest already sets platforms/wheels")
    platform_list = ", ".join(f'"{p}"' for p in platforms)
    wheel_list = ", ".join(f'"./wheels/{w.name}"' for w in wheels)
    extra = f"platforms = [{platform_list}]\nwheels = [{wheel_list}]\n"
    manifest, n = re.subn(r"^(license\s*=.*\n)", lambda m: m.group(1) + extra, manifest, count=1, flags=re.M)
    if n != 1:
        raise SystemExit("package.py: no 'license = ...' line in blender_manifest.toml to put the wheels after")
    (stage_dir / "blender_manifest.toml").write_text(manifest)
    return stage_dir


def build(out: Path, platforms: list[str], wheel_dir: Path, download: bool = True) -> list[Path]:
    """Build and validate; returns the zip file(s) written to ``out``."""
    for p in platforms:
        if p not in PLATFORM_TAGS:
            raise SystemExit(f"package.py: unknown platform {p!r}; use {', '.join(PLATFORM_TAGS)}")
    wheels = [fetch_wheel(dist, p, python, importlib.metadata.version(dist), wheel_dir, download)
              for p in platforms for dist, pythons in BUNDLED.items() for python in pythons]
    (ROOT / "build").mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory(dir=ROOT / "build", prefix="extension-") as staging:  # one per build
        return _build_staged(stage(Path(staging), wheels, platforms), out, platforms)


def _build_staged(src: Path, out: Path, platforms: list[str]) -> list[Path]:
    """Build the staged extension ``src`` into ``out`` with Blender's tool and validate each zip."""
    out.mkdir(parents=True, exist_ok=True)
    tool = blender_ext_tool()
    before = set(out.glob("*.zip"))
    cmd = [sys.executable, str(tool), "build", "--source-dir", str(src), "--output-dir", str(out)]
    if len(platforms) > 1:
        cmd.append("--split-platforms")
    subprocess.run(cmd, check=True)
    zips = sorted(set(out.glob("*.zip")) - before) or sorted(out.glob("spectral_skin_sss-*.zip"))
    for z in zips:
        proc = subprocess.run([sys.executable, str(tool), "validate", str(z)], capture_output=True, text=True)
        if proc.returncode != 0 or "Success" not in proc.stdout:
            raise SystemExit(f"package.py: {z.name} does not validate:\n{proc.stdout}{proc.stderr}")
        print(f"package.py: {z} ({z.stat().st_size / 2**20:.1f} MiB) built and validated")
    return zips


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="package.py", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "dist")
    parser.add_argument("--platforms", default="linux-x64", help="comma-separated Blender platforms")
    parser.add_argument("--wheel-dir", type=Path, default=ROOT / ".whl", help="wheel cache (default .whl/)")
    parser.add_argument("--no-download", action="store_true", help="use only wheels already in --wheel-dir")
    args = parser.parse_args(argv)
    build(args.out, [p.strip() for p in args.platforms.split(",") if p.strip()], args.wheel_dir,
          download=not args.no_download)
    return 0


if __name__ == "__main__":
    sys.exit(main())
