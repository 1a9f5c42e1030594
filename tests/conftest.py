"""Suite-wide settings."""

import pytest
import torch


@pytest.fixture(scope="session", autouse=True)
def _one_torch_thread():
    """One intra-op torch thread for the whole suite: the walker's and the fitter's small batched ops gain
    nothing from two threads, and on a busy 2-core machine OpenMP threads waiting for each other cost
    10-70x (measured).  Commands set the same default through their --threads option."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


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
