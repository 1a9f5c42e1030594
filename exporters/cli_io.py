"""The shared front of every command line (``python -m training <command>`` and ``blender_addon/bake.py``):
options, input files and output paths checked before any computing, atomic writes, one lock per output,
and the exit statuses of docs/contracts.md §2.

* Options: argparse types (:func:`count`, :func:`non_negative_int`, :func:`finite_float`, :func:`positive_float`,
  :func:`fraction`, :func:`in_range`) and :class:`OneLineParser`, whose errors are one line and exit 2.
* Inputs: :func:`check_input` — exists, right kind (file or folder), readable, and for ``.npz``, ``.h5``,
  ``.onnx``, ``.png`` and the images OpenImageIO reads, not truncated or disguised (read from the file's
  structure, cheaply: the zip directory, the HDF5 superblock, the ONNX protobuf, the PNG's IEND chunk).
* Outputs: :func:`check_output_file` (the parent folder exists and is writable, not a folder, the exact
  suffix the writer keeps, never one of the inputs) and :func:`check_output_folder` (a folder or creatable
  as one, never an input).
* Writes: :func:`atomic_file` / :func:`atomic_path` (a temporary file in the same folder, then ``os.replace``;
  removed on any error or Ctrl-C).
* :func:`output_lock`: one process per output (a lock file holding the PID; a second process is refused,
  naming the first).

Every refusal is an :class:`InputError` whose message names the file or option and what to do.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import functools
import math
import os
import signal
import sys
import tempfile
import threading
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO

#: Exit statuses (docs/contracts.md §2): success, a task that failed while running, bad input, Ctrl-C.
EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130
#: File kinds :func:`check_input` validates by content, by suffix.
CONTENT_KINDS = {".npz": "npz", ".npy": "npy", ".h5": "h5", ".hdf5": "h5", ".onnx": "onnx", ".png": "png"}
_PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


class InputError(ValueError):
    """Bad input the user can fix (exit 2); the message is one line naming what is wrong and what to do."""


class OneLineParser(argparse.ArgumentParser):
    """argparse's parser whose errors are one line on stderr (``prog: error: message``), exit 2, no usage dump."""

    def error(self, message: str):  # noqa: D401 - argparse's hook
        print(f"{self.prog}: error: {' '.join(message.split())}", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT)


# -- option types -------------------------------------------------------------------------------------------
def _number(text: str, kind: type, what: str):
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} expected, got {text!r}") from None
    if kind is float and not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"a finite number expected, got {text!r}")
    return value


def count(text: str) -> int:
    """argparse type: an integer >= 1 (photons, epochs, samples, sizes ...)."""
    value = _number(text, int, "an integer")
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text!r}")
    return value


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0 (0 usually meaning 'none' or 'all', as the option's help says)."""
    value = _number(text, int, "an integer")
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text!r}")
    return value


def finite_float(text: str) -> float:
    """argparse type: a finite number (no NaN, no infinity)."""
    return _number(text, float, "a number")


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    value = finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text!r}")
    return value


def non_negative_float(text: str) -> float:
    """argparse type: a finite number >= 0."""
    value = finite_float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text!r}")
    return value


def in_range(lo: float, hi: float, *, integer: bool = False):
    """argparse type: a finite number (an integer with ``integer``) in [lo, hi]."""
    def parse(text: str):
        value = _number(text, int, "an integer") if integer else finite_float(text)
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must lie in [{lo:g}, {hi:g}], got {text!r}")
        return value

    parse.__name__ = f"number in [{lo:g}, {hi:g}]"
    return parse


def fraction(text: str) -> float:
    """argparse type: a finite number in [0, 1]."""
    return in_range(0.0, 1.0)(text)


def require(ok: bool, message: str) -> None:
    """:class:`InputError` with ``message`` unless ``ok`` (option checks that involve several options)."""
    if not ok:
        raise InputError(message)


def check_biophysical(values, what: str) -> None:
    """:class:`InputError` unless ``values`` is a physical biophysical vector (docs/contracts.md §1 order):
    fractions in [0, 1], the epidermis thickness > 0 cm."""
    from .constants import PARAM_NAMES

    for name, value in zip(PARAM_NAMES, values, strict=True):
        ok = math.isfinite(value) and (value > 0 if name == "t_epi" else 0.0 <= value <= 1.0)
        require(ok, f"{what} {name} = {value:g} is outside its range ({'> 0 cm' if name == 't_epi' else '[0, 1]'})")


# -- input files ----------------------------------------------------------------------------------------------
def check_input(path: str | os.PathLike, what: str, kind: str = "file") -> Path:
    """``path`` as a Path if it is a usable input, else :class:`InputError` naming ``what`` (e.g. "--lut").

    ``kind``: "folder" (an existing, readable folder), "file" (an existing, readable, non-empty file, checked by
    content when its suffix is in ``CONTENT_KINDS``), or one of "npz", "npy", "h5", "onnx", "png", "image" to
    require that content whatever the suffix.
    """
    path = Path(path)
    if not path.exists():
        noun = "folder" if kind == "folder" else "file"
        raise InputError(f"{what} {path}: not found (no such {noun}); check the path")
    if kind == "folder":
        if not path.is_dir():
            raise InputError(f"{what} {path}: a file, not a folder; give the folder")
        if not os.access(path, os.R_OK | os.X_OK):
            raise InputError(f"{what} {path}: folder not readable; check its permissions")
        return path
    if path.is_dir():
        raise InputError(f"{what} {path}: a folder, not a file; give the file")
    if not os.access(path, os.R_OK):
        raise InputError(f"{what} {path}: not readable; check its permissions")
    if path.stat().st_size == 0:
        raise InputError(f"{what} {path}: empty file; rebuild or re-download it")
    content = CONTENT_KINDS.get(path.suffix.lower()) if kind == "file" else kind
    if content is not None:
        problem = _content_problem(path, content)
        if problem:
            raise InputError(f"{what} {path}: {problem}")
    return path


def _content_problem(path: Path, kind: str) -> str | None:
    """Why ``path`` is not a whole file of ``kind`` (None: it looks whole); reads headers and directories only."""
    if kind == "npz":
        try:
            with zipfile.ZipFile(path) as z:
                names = z.namelist()
        except (zipfile.BadZipFile, OSError, EOFError):
            return "not a NumPy .npz archive or truncated (zip directory unreadable); rebuild it"
        return None if all(n.endswith(".npy") for n in names) else "a zip archive but not a NumPy .npz; rebuild it"
    if kind == "npy":
        with open(path, "rb") as f:
            return None if f.read(6) == b"\x93NUMPY" else "not a NumPy .npy file; rebuild it"
    if kind == "h5":
        return _h5_problem(path)
    if kind == "onnx":
        return _onnx_problem(path)
    if kind == "png":
        with open(path, "rb") as f:
            head = f.read(8)
            f.seek(max(0, path.stat().st_size - len(_PNG_END)))
            tail = f.read()
        if head != b"\x89PNG\r\n\x1a\n":
            return "not a PNG image (wrong signature); export it again as PNG"
        if tail != _PNG_END:
            return "truncated PNG (no end chunk); export it again"
        return None
    if kind == "image":
        return _image_problem(path)
    return None


def _h5_problem(path: Path) -> str | None:
    with open(path, "rb") as f:
        if f.read(8) != _HDF5_SIGNATURE:
            return "not an HDF5 file; rebuild it"
    try:
        import h5py
    except ImportError:
        return None
    try:
        with h5py.File(path, "r", locking=False) as h5:
            h5.keys()
    except OSError as exc:
        if "unable to lock" in str(exc).lower() or getattr(exc, "errno", None) in (errno.EAGAIN, errno.EWOULDBLOCK):
            return None  # in use by a writer: its owner's lock answers that (output_lock)
        return f"HDF5 file unreadable or truncated ({' '.join(str(exc).split())[:120]}); rebuild it"
    return None


def _onnx_problem(path: Path) -> str | None:
    try:
        import onnx
    except ImportError:
        return None
    try:
        model = onnx.load(str(path), load_external_data=False)
    except Exception as exc:  # onnx raises DecodeError / its own errors for a file that is not a model
        return (f"not an ONNX model or truncated ({type(exc).__name__}); export the model again "
                "(python -m training export)")
    if not model.graph.node:
        return "not an ONNX model (no graph); export the model again (python -m training export)"
    return None


def _image_problem(path: Path) -> str | None:
    if path.suffix.lower() == ".png":
        return _content_problem(path, "png")
    from .image_input import openimageio

    oiio = openimageio()
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return f"not an image OpenImageIO can read ({' '.join(oiio.geterror().split())[:120]})"
    inp.close()
    return None


# -- output paths ---------------------------------------------------------------------------------------------
def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether ``a`` and ``b`` name the same file or folder (links and relative paths resolved)."""
    a, b = Path(a), Path(b)
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def _refuse_inputs(path: Path, what: str, inputs) -> None:
    for name, source in inputs:
        if source is not None and same_file(path, source):
            raise InputError(f"{what} {path} is the same file as {name}; write somewhere else (it would be lost)")
        if source is not None and Path(source).exists() and Path(source).is_dir() and _inside(path, source):
            raise InputError(f"{what} {path} lies inside {name} {source}; write somewhere else")


def inside(path: str | os.PathLike, folder: str | os.PathLike) -> bool:
    """Whether ``path`` lies in ``folder`` (or is it), links resolved."""
    return _inside(Path(path), folder)


def _inside(path: Path, folder) -> bool:
    try:
        Path(path).resolve().relative_to(Path(folder).resolve())
        return True
    except ValueError:
        return False


def _writable_folder(folder: Path, what: str, path: Path) -> None:
    if not folder.exists():
        raise InputError(f"{what} {path}: folder {folder} does not exist; create it first (mkdir -p {folder})")
    if not folder.is_dir():
        raise InputError(f"{what} {path}: {folder} is a file, not a folder; choose another path")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{what} {path}: folder {folder} is not writable; choose another folder")


def check_output_file(path: str | os.PathLike, what: str, *, suffixes: tuple[str, ...] = (),
                      inputs: tuple[tuple[str, str | os.PathLike | None], ...] = (),
                      overwrite: bool = True, overwrite_option: str | None = "--overwrite") -> Path:
    """``path`` as a Path if a file can be written there, else :class:`InputError` naming ``what`` ("--out").

    The parent folder exists and is writable; ``path`` is not a folder; its suffix is one of ``suffixes`` (the
    writer would append its own otherwise, e.g. np.savez's .npz) when given; it is none of ``inputs``
    ((option, path) pairs); it does not exist unless ``overwrite`` (the message names ``overwrite_option``, the
    command's way to allow it, or says that the command never overwrites when None)."""
    path = Path(path)
    if path.is_dir():
        example = path / ("out" + (suffixes or ("",))[0])
        raise InputError(f"{what} {path} is a folder; give a file name inside it (e.g. {example})")
    if suffixes and path.suffix.lower() not in suffixes:
        raise InputError(f"{what} {path}: the file must end in {' or '.join(suffixes)} (the writer would otherwise "
                         f"change the name); e.g. {path.with_name(path.name + suffixes[0])}")
    _writable_folder(path.parent if str(path.parent) else Path("."), what, path)
    _refuse_inputs(path, what, inputs)
    if path.exists() and not overwrite:
        how = f"pass {overwrite_option} to replace it or " if overwrite_option else "not overwriting it: "
        raise InputError(f"{what} {path} exists; {how}choose another name")
    if path.exists() and not os.access(path, os.W_OK):
        raise InputError(f"{what} {path} exists and is read-only; choose another name")
    return path


def check_output_folder(path: str | os.PathLike, what: str,
                        inputs: tuple[tuple[str, str | os.PathLike | None], ...] = (), writable: bool = True) -> Path:
    """``path`` as a Path if it is a writable folder or can be created (with its missing parents), else
    :class:`InputError`; never one of ``inputs`` ((option, path) pairs).  ``writable=False`` lets an existing
    read-only folder through (a command that may find its work done there).  Nothing is created here."""
    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise InputError(f"{what} {path} is a file, not a folder; give a folder")
        if writable and not os.access(path, os.W_OK | os.X_OK):
            raise InputError(f"{what} {path}: folder not writable; choose another folder")
    else:
        base = path.parent
        while not base.exists() and base != base.parent:
            base = base.parent
        if not base.is_dir():
            raise InputError(f"{what} {path}: {base} is a file, not a folder; choose another path")
        if not os.access(base, os.W_OK | os.X_OK):
            raise InputError(f"{what} {path}: cannot create it, {base} is not writable; choose another folder")
    for name, source in inputs:
        if source is not None and same_file(path, source):
            raise InputError(f"{what} {path} is the same folder as {name}; write somewhere else")
    return path


# -- atomic writes --------------------------------------------------------------------------------------------
@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary path beside ``path`` with the same suffix (writers that append a suffix keep it); on success
    it replaces ``path`` (``os.replace``), on any error or Ctrl-C it is removed and ``path`` is untouched."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".part{path.suffix}", dir=path.parent or ".")
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike, mode: str = "wb") -> Iterator[IO]:
    """An open file that becomes ``path`` when the block ends without error (:func:`atomic_path`); pass it to
    np.savez / np.save / savefig(format=...) so that they write exactly ``path``, no suffix added."""
    with atomic_path(path) as tmp, open(tmp, mode) as f:
        yield f


# -- one process per output -------------------------------------------------------------------------------------
def lock_path(output: str | os.PathLike, part: str = "", inside: bool | None = None) -> Path:
    """The lock file of ``output``: inside it (``inside``, by default when it is a folder) or beside it;
    ``part`` (e.g. a shard) lets processes that write disjoint parts of one output run together."""
    output = Path(output)
    tag = f".{part}" if part else ""
    if output.is_dir() if inside is None else inside:
        return output / f".lock{tag}"
    return output.parent / f".{output.name}{tag}.lock"


def _try_lock(fd: int) -> bool:
    """Take an exclusive, non-blocking lock on the open file ``fd``; False when another process holds it
    (flock on POSIX, msvcrt on Windows, where Blender may run the add-on)."""
    try:
        import fcntl
    except ImportError:
        import msvcrt

        try:
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
        except OSError:
            return False
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return False
    return True


def _read_holder(fd: int) -> str:
    """The PID the lock file ``fd`` holds ("unknown" when unreadable: Windows locks are mandatory)."""
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        return os.read(fd, 64).decode(errors="replace").strip() or "unknown"
    except OSError:
        return "unknown"


@contextlib.contextmanager
def output_lock(output: str | os.PathLike, what: str, part: str = "", inside: bool | None = None) -> Iterator[Path]:
    """Hold the lock of ``output`` (:func:`lock_path`) while the block runs; :class:`InputError` naming the
    holder's PID when another process holds it.  The lock file is removed on exit; the folder that holds it
    must exist."""
    path = lock_path(output, part, inside)
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        if not _try_lock(fd):
            holder = _read_holder(fd)
            os.close(fd)
            raise InputError(f"{what} {output} is in use by process {holder} (lock {path}); wait for it to finish "
                             "or choose another output") from None
        try:
            same = os.path.exists(path) and os.stat(path).st_ino == os.fstat(fd).st_ino
        except OSError:
            same = False
        if same:
            break
        os.close(fd)  # the holder removed the file as we opened it: take the new one
    try:
        os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_SET)
        os.write(fd, f"{os.getpid()}\n".encode())
        yield path
    finally:
        with contextlib.suppress(OSError):
            path.unlink()
        os.close(fd)


#: What Ctrl-C keeps when a command writes its outputs atomically and keeps no finished pieces.
NOTHING_KEPT = "nothing was written (outputs appear only when complete); run the same command again"
#: What Ctrl-C keeps for a resumable command.
RESUME_KEPT = "the finished pieces in the output are kept; run the same command again to resume"
#: Errors a command may raise for input the user can fix (exit 2, one line).
BAD_INPUT = (InputError, ValueError, FileNotFoundError, FileExistsError, PermissionError, IsADirectoryError,
             NotADirectoryError, zipfile.BadZipFile)


def guarded(prog: str, kept: str = NOTHING_KEPT, failed: tuple[type[BaseException], ...] = ()):
    """Decorator of a command's ``main(argv) -> int``: bad input (``BAD_INPUT``) -> one line, exit 2; a failed
    task (``failed``) -> one line, exit 1; Ctrl-C -> one line saying what was ``kept``, exit 130.

    Ctrl-C raises KeyboardInterrupt where Python is running; one that lands in a callback from C (numba's compiler
    calls back into Python while it compiles a kernel) is swallowed there, and the compiler then fails on its own
    half-built state.  So a Ctrl-C is also remembered (:func:`_watch_ctrl_c`): whatever error follows it, or a
    command finishing after it, ends the same way as the KeyboardInterrupt would have."""
    def wrap(main):
        @functools.wraps(main)
        def run(argv):
            interrupted, restore = _watch_ctrl_c()
            try:
                code = int(main(argv) or 0)
                return _interrupted(prog, kept) if interrupted() else code
            except SystemExit as exc:  # argparse: --help (0) or a one-line usage error (2), already printed
                return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
            except KeyboardInterrupt:
                return _interrupted(prog, kept)
            except Exception as exc:
                if interrupted():
                    return _interrupted(prog, kept)
                if isinstance(exc, failed):
                    print(f"error: {one_line(exc)}", file=sys.stderr)
                    return EXIT_FAILED
                if isinstance(exc, BAD_INPUT):
                    print(f"error: {one_line(exc)}", file=sys.stderr)
                    return EXIT_BAD_INPUT
                raise
            finally:
                restore()

        return run

    return wrap


def _interrupted(prog: str, kept: str) -> int:
    """Say that ``prog`` was interrupted and what was ``kept`` (one line); the exit status of Ctrl-C."""
    print(f"\n{prog}: interrupted: {kept}", file=sys.stderr)
    # Objects the interrupt cut short (a numba compilation, say) may fail in __del__ when the interpreter tears
    # them down; Python prints those as "Exception ignored" after the one line.
    sys.unraisablehook = _ignore_unraisable
    return EXIT_INTERRUPTED


def _watch_ctrl_c():
    """Where Ctrl-C raises KeyboardInterrupt (Python's own handler, in the main thread: not where the process was
    started with it ignored), remember each Ctrl-C as well, and drop Python's report of one swallowed in a callback
    from C; returns (the function that says whether one arrived, the function that puts Python's handler and report
    back: the report stays dropped once one arrived, see :func:`_interrupted`)."""
    arrived = threading.Event()
    if threading.current_thread() is not threading.main_thread() \
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return arrived.is_set, lambda: None

    def on_ctrl_c(signum, frame):
        arrived.set()
        signal.default_int_handler(signum, frame)

    hook = sys.unraisablehook

    def quiet_ctrl_c(unraisable) -> None:
        if not isinstance(unraisable.exc_value, KeyboardInterrupt):
            hook(unraisable)

    def restore() -> None:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        if sys.unraisablehook is quiet_ctrl_c:
            sys.unraisablehook = hook

    signal.signal(signal.SIGINT, on_ctrl_c)
    sys.unraisablehook = quiet_ctrl_c
    return arrived.is_set, restore


def _ignore_unraisable(unraisable) -> None:
    """sys.unraisablehook that drops the report (used once a command has been interrupted)."""


def one_line(exc: BaseException) -> str:
    """An exception as one line: its message (the class name if it has none), the file of an OSError added."""
    text = str(exc) or type(exc).__name__
    if isinstance(exc, OSError) and exc.filename and str(exc.filename) not in text:
        text = f"{text}: {exc.filename}"
    return " ".join(text.split())
