"""Every command line answers bad input in one line and touches nothing: each ``python -m training`` command and
``blender_addon/bake.py`` driven with missing, empty, truncated and disguised input files; NaN, zero and negative
numbers; output paths in a missing or read-only folder, of the wrong kind, equal to an input or held by another
process.  Each case must exit 2 with exactly one line on stderr naming the problem, no traceback, and leave every
file as it was (exporters.cli_io, docs/contracts.md §2).

Most cases fail before computing, so they run in this process through the dispatcher (``training.commands
.dispatch.main``); the read-only cases (as an unprivileged user when the tests run as root), a second process on
one output, Ctrl-C and a scheduler that cannot start run as real subprocesses.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import re
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np
import OpenImageIO as oiio
import pytest

from exporters.cli_io import output_lock
from training.commands import dispatch

ROOT = Path(__file__).resolve().parents[1]
DECODER = ROOT / "blender_addon" / "models" / "skin_decoder.onnx"
TONE = ["--tone", "0.1", "0.02", "0.01", "0.75", "0.9"]


# -- the files the cases use --------------------------------------------------------------------------------------
def _png(path: Path, size: int = 4) -> Path:
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(size, size, 3, "uint8"))
    assert out.write_image(np.full((size, size, 3), (200, 150, 120), np.uint8))
    out.close()
    return path


def _truncate(src: Path, dst: Path) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[: len(data) // 2])
    return dst


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> dict[str, Path]:
    """Good and bad inputs side by side in one folder (world-readable: the read-only cases run as nobody)."""
    base = Path(tempfile.mkdtemp(prefix="cli_bad_input_"))
    base.chmod(0o755)
    w: dict[str, Path] = {"base": base}
    w["npz"] = base / "good.npz"
    np.savez(w["npz"], x=np.arange(3))
    w["dir"] = base / "data"
    w["dir"].mkdir()
    with h5py.File(w["dir"] / "train.h5", "w") as f:
        f["x"] = np.arange(1000.0)
    w["h5"] = w["dir"] / "train.h5"
    w["onnx"] = base / "model.onnx"
    shutil.copy(DECODER, w["onnx"])
    w["onnx_npz"] = base / "model_named.npz"
    os.link(w["onnx"], w["onnx_npz"])  # the same model under a table's name
    w["npz2"] = base / "lut.npz"
    np.savez(w["npz2"], y=np.arange(2))
    w["png"] = _png(base / "face.png")
    w["run"] = base / "run"
    w["run"].mkdir()
    (w["run"] / "model.pt").write_bytes(b"not empty")
    (w["run"] / "run.json").write_text("{}")
    w["csv"] = base / "spectra.csv"
    w["csv"].write_text("wavelength_nm,a\n400,0.3\n700,0.5\n1000,0.6\n")
    w["empty"] = base / "empty.npz"
    w["empty"].write_bytes(b"")
    w["text"] = base / "notes.txt"
    w["text"].write_text("just some text\n")
    for suffix in ("npz", "onnx", "png", "h5"):
        w[f"disguised_{suffix}"] = base / f"disguised.{suffix}"
        w[f"disguised_{suffix}"].write_text("just some text, not a real file of this kind\n")
    w["trunc_npz"] = _truncate(w["npz"], base / "trunc.npz")
    w["trunc_onnx"] = _truncate(w["onnx"], base / "trunc.onnx")
    w["trunc_png"] = _truncate(_png(base / "big.png", 64), base / "trunc.png")
    w["bad_h5_dir"] = base / "bad_h5"
    w["bad_h5_dir"].mkdir()
    _truncate(w["h5"], w["bad_h5_dir"] / "train.h5")
    w["a_file"] = base / "a_file"
    w["a_file"].write_text("a file where a folder is expected\n")
    w["out_dir"] = base / "out_dir"
    w["out_dir"].mkdir()
    w["readonly"] = base / "readonly"
    w["readonly"].mkdir()
    w["readonly"].chmod(stat.S_IRUSR | stat.S_IXUSR | stat.S_IRGRP | stat.S_IXGRP | stat.S_IROTH | stat.S_IXOTH)
    yield w
    w["readonly"].chmod(stat.S_IRWXU)
    shutil.rmtree(base, ignore_errors=True)


def snapshot(folder: Path) -> dict[str, tuple]:
    """Every file and folder under ``folder``: kind, size, modification time and content hash."""
    found = {}
    for path in sorted(folder.rglob("*")):
        st = path.lstat()
        digest = hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else ""
        found[str(path.relative_to(folder))] = (stat.S_IFMT(st.st_mode), st.st_size, st.st_mtime_ns, digest)
    return found


# -- the cases: (command argv with {placeholders}, what the one line must name) ----------------------------------
def _cases() -> list[tuple[str, str, list[str], str]]:
    """(category, id, argv, a word the error line must contain); argv's first item is the command, ``bake.py``
    for blender_addon/bake.py."""
    c: list[tuple[str, str, list[str], str]] = []

    def add(category, argv, word, name=None):
        c.append((category, name or f"{argv[0]}:{category}:{len(c)}", argv, word))

    for kind, path in (("missing", "{base}/nope.npz"), ("empty", "{empty}"), ("truncated", "{trunc_npz}"),
                       ("disguised", "{disguised_npz}")):
        add(f"input {kind}", ["fit", "--tone-file", path, "--lut", "{npz}"], "--tone-file")
        add(f"input {kind}", ["fit", "--tone-file", "{npz}", "--lut", path], "--lut")
        add(f"input {kind}", ["train", "--dataset", "{dir}", "--fits", "{dir}", "--lut", path, "--out", "{base}/t"],
            "--lut")
        add(f"input {kind}", ["validate", "--out", "{base}/v", "--lut", path], "--lut")
        add(f"input {kind}", ["ablations", "--out", "{base}/ab", "--dataset", "{dir}", "--fits", "{dir}", "--lut",
                              path], "--lut")
        add(f"input {kind}", ["texel-table", "--model", "{onnx}", "--out", path, "--check"], "--out")
        add(f"input {kind}", ["bake.py", "--albedo", "{png}", "--out", "{base}/b", "--model", "{onnx}", "--table",
                              path], "--table")
    for kind, path in (("missing", "{base}/nope.onnx"), ("empty", "{empty}"), ("truncated", "{trunc_onnx}"),
                       ("disguised", "{disguised_onnx}")):
        add(f"input {kind}", ["texel-table", "--model", path, "--out", "{base}/tt.npz"], "--model")
        add(f"input {kind}", ["mitsuba", *TONE, "--decoder", path], "--decoder")
        add(f"input {kind}", ["realskin", "--data", "{csv}", "--decoder", path], "--decoder")
        add(f"input {kind}", ["validate", "--mitsuba", "--out", "{base}/m", "--decoder", path], "--decoder")
        add(f"input {kind}", ["bake.py", "--albedo", "{png}", "--out", "{base}/b", "--model", path], "model")
    for kind, path in (("missing", "{base}/nope.png"), ("empty", "{empty}"), ("truncated", "{trunc_png}"),
                       ("disguised", "{disguised_png}")):
        add(f"input {kind}", ["bake.py", "--albedo", path, "--out", "{base}/b", "--model", "{onnx}"], "albedo")
        add(f"input {kind}", ["bake.py", "--albedo", "{png}", "--uv-mask", path, "--out", "{base}/b", "--model",
                              "{onnx}"], "--uv-mask")
    for kind, path in (("missing", "{base}/nope"), ("disguised", "{a_file}")):
        add(f"input {kind}", ["report", "--dataset", path], "--dataset")
        add(f"input {kind}", ["report", "--fits", path], "--fits")
        add(f"input {kind}", ["train", "--dataset", path, "--fits", "{dir}", "--lut", "{npz}", "--out", "{base}/t"],
            "--dataset")
        add(f"input {kind}", ["fit", "--dataset", path, "--lut", "{npz}", "--out", "{base}/f"], "--dataset")
        add(f"input {kind}", ["export", "--run", path, "--out", "{base}/e"], "--run")
        add(f"input {kind}", ["dataset", "--summary", "--out", path], "--out")
        add(f"input {kind}", ["realskin", "--data", path if kind == "missing" else "{dir}"], "--data")
    for argv in (["report", "--dataset", "{bad_h5_dir}"], ["dataset", "--out", "{bad_h5_dir}"],
                 ["fit", "--dataset", "{bad_h5_dir}", "--lut", "{npz}", "--out", "{base}/f"],
                 ["train", "--dataset", "{bad_h5_dir}", "--fits", "{dir}", "--lut", "{npz}", "--out", "{base}/t"]):
        add("input truncated", argv, "train.h5")
    add("input disguised", ["report", "--dataset", "{dir}", "--fits", "{base}"], "disguised.h5")
    add("input disguised", ["bake.py", "--albedo", "{text}", "--out", "{base}/b", "--model", "{onnx}"], "--albedo")

    numbers = {
        "simulate-layers": (["--layer", "1", "10", "0.8", "inf"], [("--photons", ("0", "-1", "nan")),
                                                                   ("--n-medium", ("nan", "0")),
                                                                   ("--illumination", ("collimated:90",
                                                                                       "collimated:nan",
                                                                                       "collimated:-5", "oblique"))]),
        "simulate": ([*TONE, "--out", "{base}/s.npz"], [("--photons", ("0", "-1", "1", "nan"))]),
        "lut": (["--albedo-n", "4", "--g-n", "4", "--out", "{base}/l.npz"],
                [("--photons", ("0", "-1", "nan")), ("--threads", ("-1", "0")), ("--g-min", ("nan",)),
                 ("--albedo-max", ("2",))]),
        "dataset": (["--out", "{base}/d"], [("--threads", ("0", "-1")), ("--device", ("tpu", "cuda:x"))]),
        "fit": (["--tone-file", "{npz}", "--lut", "{npz}"], [("--chunk-tones", ("0",)), ("--wavelength-stride", ("0",)),
                                                             ("--max-tones", ("-1",)), ("--threads", ("-1",))]),
        "train": (["--dataset", "{dir}", "--fits", "{dir}", "--lut", "{npz}", "--out", "{base}/t"],
                  [("--batch", ("0", "-2")), ("--epochs", ("-1", "0")), ("--lr", ("nan", "0", "inf")),
                   ("--encoder-share", ("2",)), ("--threads", ("-1",)), ("--k", ("0",))]),
        "export": (["--run", "{run}", "--out", "{base}/e"], [("--max-mb", ("nan", "0", "-1")),
                                                            ("--parity-n", ("0", "-5"))]),
        "validate": (["--out", "{base}/v", "--lut", "{npz}"],
                     [("--wavelength-step-nm", ("0",)), ("--threads", ("0",)), ("--gt-photons", ("0",)),
                      ("--baseline-scale", ("nan",)), ("--photons", ("-1",))]),
        "ablations": (["--out", "{base}/ab", "--quick"], [("--epochs", ("0",)), ("--gt-photons", ("-1",)),
                                                          ("--threads", ("0",)), ("--shape-weight", ("nan",))]),
        "swatches": (["--out", "{base}/sw.png"], [("--photons", ("0", "nan")), ("--threads", ("-1",))]),
        "mitsuba": ([*TONE, "--decoder", "{onnx}"], [("--spp", ("0",)), ("--photons", ("-1",)),
                                                      ("--wavelengths", ("2000", "nan"))]),
        "realskin": (["--data", "{csv}", "--no-decoder"], [("--subjects", ("0", "-1")), ("--photons", ("0",)),
                                                             ("--wavelength-stride", ("0",))]),
        "resampling": (["--out", "{base}/r"], [("--photons", ("0",)), ("--repeats", ("-1",)), ("--threads", ("0",))]),
        "demo": (["--out", "{base}/demo"], [("--render-size", ("0", "-1")), ("--photons", ("-1",)),
                                            ("--samples", ("0",)), ("--threads", ("0",))]),
        "texel-table": (["--model", "{onnx}", "--out", "{base}/tt.npz"],
                        [("--step", ("0", "nan", "-0.1")), ("--ior", ("nan", "0.5")), ("--min-mfp-m", ("-1", "nan")),
                         ("--threads", ("-1",))]),
        "edit-table": (["--out", "{base}/et.npz"], [("--step", ("0", "nan", "-0.1")), ("--threads", ("-1",))]),
        "bake.py": (["--albedo", "{png}", "--out", "{base}/b", "--model", "{onnx}"],
                    [("--memory-mb", ("nan", "0", "-64")), ("--threads", ("-1",)), ("--prune-share", ("2", "nan")),
                     ("--ior", ("nan",))]),
    }
    for command, (base, options) in numbers.items():
        for option, values in options:
            for value in values:
                add(f"number {value}", [command, *base, option, value], option)
    add("number nan", ["simulate", "--tone", "nan", "0.02", "0.01", "0.75", "0.9", "--photons", "10", "--out",
                       "{base}/s.npz"], "--tone")
    add("number negative", ["simulate", "--tone", "0.1", "0.02", "-0.01", "0.75", "0.9", "--photons", "10",
                            "--out", "{base}/s.npz"], "t_epi")
    add("number zero", ["mitsuba", "--tone", "0.1", "0.02", "0", "0.75", "0.9", "--decoder", "{onnx}"], "t_epi")
    add("number nan", ["simulate-layers", "--layer", "nan", "10", "0.8", "inf", "--photons", "10"], "--layer")
    add("number negative", ["simulate-layers", "--layer", "1", "10", "0.8", "-1", "--photons", "10"], "THICKNESS")
    for value in ("nan", "0", "-1"):
        add(f"number {value}", ["bake.py", "--albedo", "{png}", "--out", "{base}/b", "--model", "{onnx}",
                                "--unit-scale", value], "unit scale")
    add("number too many", ["realskin", "--data", "{csv}", "--no-decoder", "--subjects", "5"], "--subjects")

    file_outputs = {
        "simulate": ([*TONE, "--photons", "10"], "--out", ".npz"),
        "lut": (["--albedo-n", "4", "--g-n", "4", "--photons", "10"], "--out", ".npz"),
        "fit": (["--tone-file", "{npz}", "--lut", "{npz}"], "--out", ".npz"),
        "swatches": ([], "--out", ".png"),
        "texel-table": (["--model", "{onnx}"], "--out", ".npz"),
        "reflectance-tables": (["--build"], "--out", ".npz"),
        "channel-matrix": ([], "--out", ".npy"),
        "report": (["--dataset", "{dir}"], "--out", ".md"),
        "bench": (["--only", "training.bench.foundation"], "--out", ".md"),
        "demo": (["--out", "{base}/demo"], "--figure", ".png"),
    }
    for command, (base, option, suffix) in file_outputs.items():
        add("output missing parent", [command, *base, option, f"{{base}}/no/such/folder/x{suffix}"], option)
        add("output wrong kind", [command, *base, option, "{out_dir}"], option)
        if command not in ("report",):
            add("output renamed", [command, *base, option, "{base}/x.txt"], option)
    add("output exists", ["fit", "--tone-file", "{npz}", "--lut", "{npz}", "--out", "{npz}"], "--out")
    add("output exists", ["report", "--dataset", "{dir}", "--out", "{csv}"], "--overwrite")
    add("output exists", ["texel-table", "--model", "{onnx}", "--out", "{npz}"], "--overwrite")
    add("output is input", ["texel-table", "--model", "{onnx}", "--out", "{onnx}", "--overwrite"], ".npz")
    add("output is input", ["texel-table", "--model", "{onnx_npz}", "--out", "{onnx_npz}", "--overwrite"],
        "same file")
    add("output is input", ["fit", "--tone-file", "{npz}", "--lut", "{npz2}", "--out", "{npz2}"], "--out")

    folder_outputs = {
        "dataset": ["--preset", "ci"],
        "fit": ["--dataset", "{dir}", "--lut", "{npz}"],
        "train": ["--dataset", "{dir}", "--fits", "{dir}", "--lut", "{npz}"],
        "export": ["--run", "{run}"],
        "validate": ["--lut", "{npz}"],
        "ablations": ["--dataset", "{dir}", "--fits", "{dir}", "--lut", "{npz}"],
        "realskin": ["--data", "{csv}", "--no-decoder"],
        "resampling": [],
        "demo": [],
        "bake.py": ["--albedo", "{png}", "--model", "{onnx}"],
    }
    for command, base in folder_outputs.items():
        add("output wrong kind", [command, *base, "--out", "{a_file}"], "--out")
        add("output missing parent", [command, *base, "--out", "{a_file}/sub"], "--out")
    for command, base in (("fit", ["--dataset", "{dir}", "--lut", "{npz}"]),
                          ("train", ["--dataset", "{dir}", "--fits", "{dir}", "--lut", "{npz}"]),
                          ("export", ["--run", "{run}"]),
                          ("validate", ["--lut", "{npz}", "--dataset", "{dir}"]),
                          ("ablations", ["--dataset", "{dir}", "--fits", "{dir}", "--lut", "{npz}"])):
        source = "{run}" if command == "export" else "{dir}"
        add("output is input", [command, *base, "--out", source], "--out")
    add("output other", ["bench", "--only", "nosuchmodule", "--out", "{base}/bench.md"], "nosuchmodule")
    return c


CASES = _cases()


def _argv(argv: list[str], w: dict[str, Path]) -> list[str]:
    return [a.format(**{k: str(v) for k, v in w.items()}) for a in argv]


def _bake_main():
    spec = importlib.util.spec_from_file_location("bake_script", ROOT / "blender_addon" / "bake.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main


def run_in_process(argv: list[str], capsys) -> tuple[int, str]:
    """Exit status and stderr of one command run through its real entry point (argparse exits included)."""
    capsys.readouterr()
    try:
        if argv[0] == "bake.py":
            code = _bake_main()(argv[1:])
        else:
            code = dispatch.main(argv)
    except SystemExit as exc:
        code = exc.code
    return code, capsys.readouterr().err


#: What the one line must say about an input file, by category, beside the option's name: the problem itself.
PROBLEM = {"input missing": r"not found", "input empty": r"empty file", "input truncated": r"truncated",
           "input disguised": r"\bnot an? (NumPy|ONNX|PNG|HDF5|image)\b|a (file|folder), not a (folder|file)"}


def assert_one_line(code, err: str, word: str) -> None:
    assert code == 2, err
    assert "Traceback" not in err, err
    assert err.count("\n") == 1 and err.endswith("\n"), repr(err)
    assert word.lower() in err.lower(), err


@pytest.mark.parametrize(("category", "argv", "word"), [(c[0], c[2], c[3]) for c in CASES],
                         ids=[c[1] for c in CASES])
def test_bad_input_is_one_line_and_touches_nothing(world, capsys, category, argv, word):
    before = snapshot(world["base"])
    code, err = run_in_process(_argv(argv, world), capsys)
    assert_one_line(code, err, word)
    if category in PROBLEM:
        assert re.search(PROBLEM[category], err), f"{category}: the message does not name the problem: {err}"
    assert snapshot(world["base"]) == before


def test_every_command_is_covered():
    covered = {c[2][0] for c in CASES}
    assert covered == set(dispatch.COMMANDS) | {"bake.py"}, set(dispatch.COMMANDS) | {"bake.py"} - covered


def test_a_held_output_names_its_process(world, capsys):
    """Another process on the same output (its lock held): refused with that process's PID, nothing touched."""
    cases = [(["dataset", "--preset", "ci", "--out", "{out_dir}"], "{out_dir}"),
             (["train", "--dataset", "{dir}", "--fits", "{dir}", "--lut", "{npz}", "--out", "{out_dir}"], "{out_dir}"),
             (["lut", "--albedo-n", "4", "--g-n", "4", "--photons", "10", "--out", "{base}/held.npz"],
              "{base}/held.npz"),
             (["bake.py", "--albedo", "{png}", "--model", "{onnx}", "--out", "{out_dir}"], "{out_dir}"),
             (["realskin", "--data", "{csv}", "--no-decoder", "--out", "{out_dir}"], "{out_dir}"),
             (["validate", "--lut", "{npz}", "--out", "{out_dir}", "--tones", "R01"], "{out_dir}")]
    for argv, output in cases:
        with output_lock(_argv([output], world)[0], "test"):
            before = snapshot(world["base"])
            code, err = run_in_process(_argv(argv, world), capsys)
            assert_one_line(code, err, "in use by process")
            assert str(os.getpid()) in err
            assert snapshot(world["base"]) == before
    assert not list(world["base"].rglob("*.lock")) and not (world["out_dir"] / ".lock").exists()


# -- real subprocesses ---------------------------------------------------------------------------------------------
def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT), "HOME": tempfile.gettempdir()}


def _command(argv: list[str]) -> list[str]:
    if argv[0] == "bake.py":
        return [sys.executable, str(ROOT / "blender_addon" / "bake.py"), *argv[1:]]
    return [sys.executable, "-m", "training", *argv]


def _read_only_folder(world) -> Path:
    """A folder this process cannot write: the chmod-ed one, or for root (who ignores permissions) /proc/sys,
    which the kernel keeps read-only even for root."""
    if os.access(world["readonly"], os.W_OK):
        if os.access("/proc/sys", os.W_OK):
            pytest.skip("no folder here that this user cannot write")
        return Path("/proc/sys")
    return world["readonly"]


@pytest.mark.parametrize("argv", [
    ["simulate", *TONE, "--photons", "10", "--out", "{ro}/s.npz"],
    ["lut", "--albedo-n", "4", "--g-n", "4", "--photons", "10", "--out", "{ro}/l.npz"],
    ["texel-table", "--model", "{onnx}", "--out", "{ro}/t.npz"],
    ["swatches", "--out", "{ro}/sw.png"],
    ["channel-matrix", "--out", "{ro}/m.npy"],
    ["dataset", "--preset", "ci", "--out", "{ro}/d"],
    ["train", "--dataset", "{dir}", "--fits", "{dir}", "--lut", "{npz}", "--out", "{ro}/t"],
    ["export", "--run", "{run}", "--out", "{ro}/e"],
    ["validate", "--lut", "{npz}", "--out", "{ro}/v"],
    ["report", "--dataset", "{dir}", "--out", "{ro}/r.md"],
    ["bench", "--only", "training.bench.foundation", "--out", "{ro}/b.md"],
    ["bake.py", "--albedo", "{png}", "--model", "{onnx}", "--out", "{ro}/maps"],
], ids=lambda a: a[0])
def test_read_only_folder(world, capsys, argv):
    """An output in a folder this user cannot write: refused before computing, nothing touched."""
    ro = _read_only_folder(world)
    before = snapshot(world["base"])
    code, err = run_in_process(_argv(argv, {**world, "ro": ro}), capsys)
    assert_one_line(code, err, "writable")
    assert snapshot(world["base"]) == before


#: Run as ``python -c _AS_FROM_A_TERMINAL ARGS``: Ctrl-C back to its default and unblocked, then ``python ARGS`` in
#: the same process (exec keeps both, and Python then turns Ctrl-C into KeyboardInterrupt as under a terminal).
_AS_FROM_A_TERMINAL = ("import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
                       "signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT}); "
                       "os.execv(sys.executable, [sys.executable, *sys.argv[1:]])")
_SIGINT_BIT = 1 << (signal.SIGINT - 1)


def _signal_masks(pid: int) -> dict[str, int]:
    """The ignored and the blocked signals of process ``pid`` (/proc/PID/status, bit n - 1 for signal n)."""
    fields = dict(line.split(":", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines() if ":" in line)
    return {name: int(fields[name].strip(), 16) for name in ("SigIgn", "SigBlk")}


def test_second_process_then_ctrl_c(tmp_path):
    """A dataset run holds its folder: a second run on it exits 2 naming the first's PID; Ctrl-C ends the first
    with one line saying what was kept and how to resume (exit 130)."""
    out = tmp_path / "d"
    # the direct estimator on one walking thread: the ci build then takes over 3 minutes (98 s on two idle
    # cores), so the first run is still walking when the test interrupts it, however long a loaded machine
    # takes to start the second process (the reweighted ci build ends in ~30 s); it returns to Python after each
    # tone's walk (a larger preset's walk batches can outlast the time the test gives Ctrl-C on a loaded machine;
    # on a shared 2-core machine running the suite's other worker a tone's walk took over 60 s, so the test
    # waits up to 180 s)
    # the first run starts as from a terminal, Ctrl-C neither ignored nor blocked: a child inherits both from the
    # process that starts it, and a suite started in the background (`nohup make test &`: a shell starts background
    # jobs with SIGINT ignored) passed the dataset run an ignored Ctrl-C, so it walked on to the end
    direct = ["--preset", "ci", "--method", "direct", "--out", str(out)]
    first = subprocess.Popen([sys.executable, "-c", _AS_FROM_A_TERMINAL, "-m", "training", "dataset", *direct,
                              "--no-progress"], env={**_env(), "NUMBA_NUM_THREADS": "1"},
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        deadline = time.monotonic() + 90
        while not (out / ".lock").exists() and time.monotonic() < deadline and first.poll() is None:
            time.sleep(0.2)
        assert (out / ".lock").exists(), first.stderr.read() if first.poll() is not None else "no lock in 90 s"
        second = subprocess.run(_command(["dataset", *direct]), capture_output=True,
                                text=True, timeout=120, env=_env(), cwd=ROOT)
        assert_one_line(second.returncode, second.stderr, "in use by process")
        assert str(first.pid) in second.stderr
        assert first.poll() is None, "the first run ended before the test could interrupt it"
        masks = _signal_masks(first.pid)
        assert not (masks["SigIgn"] | masks["SigBlk"]) & _SIGINT_BIT, f"Ctrl-C ignored or blocked in the run: {masks}"
        first.send_signal(signal.SIGINT)
        _, err = first.communicate(timeout=180)
    finally:
        if first.poll() is None:
            first.kill()
    assert first.returncode == 130, err
    assert "Traceback" not in err and err.strip().count("\n") == 0, err
    assert "interrupted" in err and "run the same command again" in err
    assert not (out / ".lock").exists()


#: A guarded command whose Ctrl-C lands in a callback from C, as one does while numba compiles a kernel (its
#: compiler calls back into Python): Python swallows the KeyboardInterrupt there, and the command then fails on the
#: state the interrupt left ("fail") or runs on to its end ("finish").
_CTRL_C_IN_A_CALLBACK = """
import ctypes, os, signal, sys
from exporters.cli_io import RESUME_KEPT, guarded

@guarded("python -m training dataset", RESUME_KEPT)
def main(argv):
    @ctypes.CFUNCTYPE(None)
    def callback():
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(100000):  # Python runs its Ctrl-C handler here, inside the callback
            pass

    callback()
    if argv == ["fail"]:
        raise RuntimeError("no compiled object yet for <Library '_exponential_slow'>")
    return 0

sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("then", ["fail", "finish"])
def test_ctrl_c_swallowed_in_a_callback_still_ends_the_command(then):
    """Ctrl-C during a numba compilation: whether the compiler then fails or the command runs on, it ends as
    Ctrl-C does, one line and exit 130, without Python's report of the swallowed interrupt or a traceback."""
    proc = subprocess.run([sys.executable, "-c", _CTRL_C_IN_A_CALLBACK, then], capture_output=True, text=True,
                          timeout=60, env=_env(), cwd=ROOT)
    assert proc.returncode == 130, proc.stderr
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr, proc.stderr
    assert proc.stderr.strip().count("\n") == 0 and "interrupted" in proc.stderr, proc.stderr


@pytest.mark.parametrize("scheduler", ["slurm", "tcp://127.0.0.1:9"])
def test_scheduler_that_cannot_start(tmp_path, scheduler):
    """No sbatch / nothing listening: one line within 30 s, exit 2, nothing written."""
    env = {**_env(), "PATH": os.path.dirname(sys.executable) + os.pathsep + "/usr/bin:/bin"}
    start = time.monotonic()
    proc = subprocess.run(_command(["lut", "--albedo-n", "4", "--g-n", "4", "--photons", "10", "--out",
                                    str(tmp_path / "l.npz"), "--scheduler", scheduler]),
                          capture_output=True, text=True, timeout=60, env=env, cwd=ROOT)
    assert time.monotonic() - start < 30
    assert_one_line(proc.returncode, proc.stderr, "--scheduler")
    assert list(tmp_path.iterdir()) == []


def test_a_truncated_part_file_on_resume(tmp_path, capsys):
    """lut resumes from its part files: one cut short is named, with what to do, before any walking."""
    argv = ["lut", "--albedo-n", "4", "--g-n", "2", "--photons", "20", "--max-steps", "50", "--out",
            str(tmp_path / "lut.npz"), "--no-progress", "--compile", "off"]
    code, err = run_in_process(argv, capsys)
    assert code == 0, err
    part = tmp_path / "lut.npz.parts" / "g_0001.npz"
    _truncate(part, part)
    before = snapshot(tmp_path)
    code, err = run_in_process(argv, capsys)
    assert_one_line(code, err, "g_0001.npz")
    assert "run the same command again" in err
    assert snapshot(tmp_path) == before


def test_a_cuda_device_torch_does_not_see_is_one_line(world, capsys):
    """``--device cuda`` where torch sees no GPU: the one-line refusal, not torch's traceback."""
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has a CUDA device")
    before = snapshot(world["base"])
    code, err = run_in_process(_argv(["dataset", "--out", "{base}/d", "--device", "cuda"], world), capsys)
    assert_one_line(code, err, "CUDA")
    assert snapshot(world["base"]) == before
