"""The supported Blenders as test cases, and one way to run a check script in each of them.

The oldest (bpy 4.2 LTS, Python 3.11) and the newest (bpy 5.3, Python 3.13) live in their own virtual environments,
which ``make test`` creates (``make blender-envs``: .venv-blender42, .venv-blender53); the project's own (bpy 5.0.1)
is this interpreter.  A check script installs the extension zip with a sandboxed user folder and prints one line
``RESULT <json>``; a missing environment skips its case and says how to make it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: (case, the interpreter, the Blender version it must report, its Python).
BLENDERS = [
    ("4.2", ROOT / ".venv-blender42" / "bin" / "python", "4.2.", "3.11"),
    ("5.0-project", Path(sys.executable), "5.0.", "3.11"),
    ("5.3", ROOT / ".venv-blender53" / "bin" / "python", "5.3.", "3.13"),
]
IDS = [b[0] for b in BLENDERS]


def run_check(python: Path, check: Path, ext_zip: Path, tmp_path: Path, timeout: float, *args: str) -> dict:
    """Run ``check`` (a script taking the zip, a folder and ``args``) with ``python`` in ``tmp_path``; its RESULT as a
    dict.

    Skips when the interpreter is missing; fails with the script's output when it exits non-zero (a hang is a
    timeout, a crash a signal) or prints no RESULT line.
    """
    if not python.is_file():
        pytest.skip(f"{python.parent.parent.name} is missing: `make blender-envs` creates it (make test does)")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["BLENDER_USER_RESOURCES"] = str(tmp_path / "user")
    proc = subprocess.run([str(python), str(check), str(ext_zip), str(tmp_path), *args], capture_output=True, text=True,
                          timeout=timeout, env=env, cwd=tmp_path)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT")]
    assert proc.returncode == 0 and lines, f"exit status {proc.returncode}\n{proc.stdout[-2000:]}{proc.stderr[-3000:]}"
    return json.loads(lines[-1][len("RESULT"):])
