"""Suite-wide settings and fixtures."""

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]


def pytest_configure(config):
    """Each test process (each pytest-xdist worker) gets a temporary folder of its own, as TMPDIR and for
    ``tempfile``: the tests that check that a bake leaves no temporary files behind look in that folder, where
    another worker's bake running at the same moment would otherwise show."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    folder = Path(tempfile.mkdtemp(prefix=f"skin-sss-tests-{worker}-"))
    config._skin_sss_tmp = folder
    os.environ["TMPDIR"] = str(folder)
    tempfile.tempdir = str(folder)


def pytest_unconfigure(config):
    folder = getattr(config, "_skin_sss_tmp", None)
    if folder is not None:
        tempfile.tempdir = None
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(scope="session", autouse=True)
def _one_torch_thread():
    """One intra-op torch thread for the whole suite: the walker's and the fitter's small batched ops gain
    nothing from two threads, and on a busy 2-core machine OpenMP threads waiting for each other cost
    10-70x (measured).  Commands set the same default through their --threads option."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="session")
def ext_zip(tmp_path_factory) -> Path:
    """The extension zip ``make extension`` builds for this platform (blender_addon/package.py, validated by
    Blender's own extension tool), built once per test process."""
    out = tmp_path_factory.mktemp("dist")
    proc = subprocess.run([sys.executable, str(ROOT / "blender_addon" / "package.py"), "--out", str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "built and validated" in proc.stdout
    zips = list(out.glob("spectral_skin_sss-*.zip"))
    assert len(zips) == 1
    return zips[0]


@pytest.fixture()
def registered():
    """The add-on registered directly (no preferences entry: its default model) in an empty home file: a test may
    open, append and unregister files and the add-on freely."""
    import bpy

    import blender_addon

    bpy.ops.wm.read_homefile(use_empty=True)
    blender_addon.register()
    yield
    blender_addon.unregister()


@pytest.fixture()
def addon():
    """The extension enabled in a fresh factory scene (one bake thread); yields its preferences."""
    import addon_utils
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert addon_utils.enable("blender_addon", default_set=True, handle_error=None) is not None
    prefs = bpy.context.preferences.addons["blender_addon"].preferences
    prefs.threads = 1
    yield prefs
    addon_utils.disable("blender_addon", default_set=True)
